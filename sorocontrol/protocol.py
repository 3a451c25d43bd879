r"""The board's wire protocol: versioned, checksummed binary frames over TCP, a challenge-response login, and
a message authentication code on every frame after it.

The specification, for implementers of other clients, is ``docs/board-protocol.md``; this module is its
reference implementation, shared by the board server (:mod:`sorocontrol.server`) and the host client
(:class:`sorocontrol.Board`).

Frame (all integers little-endian)::

    offset  size  field
    0       2     magic b"SB"
    2       1     protocol version (PROTOCOL_VERSION = 2)
    3       1     message type (MessageType)
    4       4     payload length L, uint32, at most MAX_PAYLOAD
    8       L     payload (layout per type, below)
    8+L     4     CRC-32 (zlib/IEEE 802.3) of bytes 0 .. 8+L-1

A receiver rejects a frame with another magic, another version, an unknown type, L > MAX_PAYLOAD, a CRC
mismatch or a payload of the wrong size for its type: :class:`~sorofem.errors.ProtocolError` naming which.
The server answers a rejected frame with an ``ERROR`` frame and closes the connection; it never crashes.

Session::

    server -> HELLO   version, channel count n, watchdog timeout, per-channel limits, 32-byte nonce Ns
    client -> AUTH    32-byte nonce Nc, HMAC-SHA256(secret, b"soro-client" | Ns | Nc)
    server -> READY   HMAC-SHA256(secret, b"soro-server" | Nc | Ns)   (the client checks it: mutual proof)
    client -> SET / READ / HEARTBEAT / VENT, each answered by a STATE frame (or ERROR)
    client -> BYE     (server vents and closes)

After READY every frame, both ways, is *sealed* (:class:`Session`): its payload is
``uint64 sequence | body | HMAC-SHA256(K_dir, header | sequence | body)`` with the session key
:math:`K = \mathrm{HMAC}(secret, \texttt{"soro-session"} | N_s | N_c)` and one direction key
:math:`K_{dir} = \mathrm{HMAC}(K, \texttt{"client->board"})` or ``"board->client"``. The sequence number
starts at 1 in each direction and grows by exactly 1 per frame, so a forged, replayed, reordered or dropped
frame is an error (the board vents and drops the connection). The secret never crosses the wire; a replayed
AUTH fails because Ns is fresh per connection. Pressures are gauge pressures in pascal (float64).
"""
import enum
import hashlib
import hmac
import math
import os
import socket
import string
import struct
import zlib
from dataclasses import dataclass, field

import numpy as np

from sorofem.errors import ProtocolError

__all__ = ["PROTOCOL_VERSION", "MAGIC", "MAX_PAYLOAD", "MAX_CHANNELS", "HEADER", "MAC_SIZE", "MIN_SECRET_BITS",
           "MessageType", "Flag", "ErrorCode", "Hello", "State", "Session", "encode", "decode", "read_frame",
           "FrameReader", "send_frame", "client_proof", "server_proof", "secret_bytes", "secret_bits",
           "read_secret_file",
           "error_code", "new_nonce", "pack_hello", "unpack_hello", "pack_pressures", "unpack_pressures", "pack_state",
           "unpack_state", "pack_error", "unpack_error"]

PROTOCOL_VERSION = 2
MAGIC = b"SB"
MAX_PAYLOAD = 4096      # bytes; the largest legal payload (HELLO with 64 channels) is < 1.2 kB
MAX_CHANNELS = 64
NONCE_SIZE = 32
HEADER = struct.Struct("<2sBBI")        # magic, version, type, payload length
CRC = struct.Struct("<I")
MAC_SIZE = 32           # bytes of HMAC-SHA256 tag on a sealed frame
MIN_SECRET_BITS = 128   # a shared secret must carry at least 16 bytes of entropy (estimated, see secret_bits)
MAKE_SECRET = "head -c 32 /dev/urandom | base64 > FILE"


class MessageType(enum.IntEnum):
    """Message types (byte 3 of a frame)."""
    HELLO = 1       # server -> client, first frame
    AUTH = 2        # client -> server
    READY = 3       # server -> client, login accepted
    SET = 4         # client -> server: set-points [Pa]
    READ = 5        # client -> server: ask for the state
    HEARTBEAT = 6   # client -> server: keep the watchdog fed without changing set-points
    VENT = 7        # client -> server: all set-points to 0 Pa at once (no rate limit)
    STATE = 8       # server -> client: the answer to SET/READ/HEARTBEAT/VENT
    ERROR = 9       # either way: code + message; the server closes after sending one
    BYE = 10        # client -> server: vent and close


class Flag(enum.IntFlag):
    """Per-channel status bits of a STATE frame."""
    CLAMPED = 1         # the last set-point was outside [p_min, p_max] and was clamped
    RATE_LIMITED = 2    # the applied set-point is still slewing toward the request
    VENTED = 4          # the channel was vented (watchdog, VENT, error or shutdown) since the last SET
    SENSOR_FAULT = 8    # the read-back could not be taken (I2C error); the reading is the last good one


class ErrorCode(enum.IntEnum):
    MALFORMED = 1
    VERSION = 2
    AUTH = 3
    BUSY = 4
    UNEXPECTED = 5
    SIZE = 6
    INTERNAL = 7
    INTEGRITY = 8       # a sealed frame with a bad MAC or an out-of-order sequence number
    WATCHDOG = 9        # the board heard nothing valid for its watchdog time: it vented and dropped the client


def error_code(exc):
    """The :class:`ErrorCode` that answers the ProtocolError ``exc`` (by what its message names)."""
    text = str(exc)
    if "protocol version" in text:
        return ErrorCode.VERSION
    if "MAX_PAYLOAD" in text:
        return ErrorCode.SIZE
    if text.startswith(("unexpected", "expected AUTH")):
        return ErrorCode.UNEXPECTED
    if "MAC" in text or "sequence number" in text:
        return ErrorCode.INTEGRITY
    return ErrorCode.MALFORMED


@dataclass(frozen=True)
class Hello:
    """What the server announces: ``channels``, ``watchdog`` timeout [s], per-channel ``p_min``/``p_max``
    [Pa] and slew-rate limit ``rate`` [Pa/s], the loop ``board_rate`` [Hz] and the login ``nonce``."""
    version: int
    channels: int
    watchdog: float
    board_rate: float
    p_min: np.ndarray
    p_max: np.ndarray
    rate: np.ndarray
    nonce: bytes


@dataclass
class State:
    """One STATE frame: board ``time`` [s since the server started], the client's ``sequence`` number it
    answers, the ``requested`` and ``applied`` set-points and the ``measured`` pressures [Pa], per-channel
    ``flags`` (:class:`Flag`), and extra ``sensors`` values (simulated plants report e.g. beam positions)."""
    time: float
    sequence: int
    requested: np.ndarray
    applied: np.ndarray
    measured: np.ndarray
    flags: np.ndarray
    sensors: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def flagged(self, flag):
        """Indices of the channels carrying ``flag``."""
        return np.flatnonzero(self.flags & int(flag))


# ---- frames -------------------------------------------------------------------------------------------

def encode(mtype, payload=b""):
    """One frame (bytes) of type ``mtype`` carrying ``payload``."""
    payload = bytes(payload)
    if len(payload) > MAX_PAYLOAD:
        raise ProtocolError(f"payload of {len(payload)} bytes exceeds MAX_PAYLOAD = {MAX_PAYLOAD}")
    head = HEADER.pack(MAGIC, PROTOCOL_VERSION, int(MessageType(mtype)), len(payload))
    return head + payload + CRC.pack(zlib.crc32(head + payload))


def _check_header(head):
    magic, version, mtype, length = HEADER.unpack(head)
    if magic != MAGIC:
        raise ProtocolError(f"bad magic {magic!r} (expected {MAGIC!r}): not a soro board frame")
    if version != PROTOCOL_VERSION:
        raise ProtocolError(f"protocol version {version}, this side speaks {PROTOCOL_VERSION}: update the "
                            "client or the board software so that both match")
    try:
        mtype = MessageType(mtype)
    except ValueError:
        raise ProtocolError(f"unknown message type {mtype}") from None
    if length > MAX_PAYLOAD:
        raise ProtocolError(f"payload length {length} exceeds MAX_PAYLOAD = {MAX_PAYLOAD}")
    return mtype, length


def decode(frame):
    """``(type, payload)`` of one complete frame (bytes); ProtocolError on any defect."""
    frame = bytes(frame)
    if len(frame) < HEADER.size + CRC.size:
        raise ProtocolError(f"truncated frame ({len(frame)} bytes, a frame has at least "
                            f"{HEADER.size + CRC.size})")
    mtype, length = _check_header(frame[:HEADER.size])
    end = HEADER.size + length
    if len(frame) != end + CRC.size:
        raise ProtocolError(f"frame of {len(frame)} bytes, its header announces {end + CRC.size}")
    (crc,) = CRC.unpack(frame[end:])
    if crc != zlib.crc32(frame[:end]):
        raise ProtocolError("checksum mismatch (corrupted frame)")
    return mtype, frame[HEADER.size:end]


class FrameReader:
    """Incremental decoder: ``feed(bytes)`` returns the complete frames received so far as ``(type,
    payload)``; a defect raises ProtocolError (the stream cannot be resynchronized after one)."""

    def __init__(self):
        self._buf = bytearray()

    def feed(self, data):
        self._buf += data
        out = []
        while len(self._buf) >= HEADER.size:
            _, length = _check_header(bytes(self._buf[:HEADER.size]))
            total = HEADER.size + length + CRC.size
            if len(self._buf) < total:
                break
            out.append(decode(bytes(self._buf[:total])))
            del self._buf[:total]
        return out

    @property
    def pending(self):
        """Bytes of an incomplete frame held back."""
        return len(self._buf)


def _recv_exact(sock, n):
    chunks, got = [], 0
    while got < n:
        chunk = sock.recv(n - got)
        if not chunk:
            raise ConnectionError(f"connection closed ({got} of {n} bytes of a frame received)")
        chunks.append(chunk)
        got += len(chunk)
    return b"".join(chunks)


_NOSIGNAL = getattr(socket, "MSG_NOSIGNAL", 0)


def send_frame(sock, frame):
    """Send ``frame`` (bytes) on ``sock``. A peer that has gone raises OSError (EPIPE) and never SIGPIPE,
    which a host library may have set to abort the process (PETSc's signal handlers do)."""
    sock.sendall(frame, _NOSIGNAL)


def read_frame(sock):
    """Block until one frame arrives on ``sock``; ``(type, payload)``. ProtocolError on a defect,
    ConnectionError when the peer closes, ``socket.timeout`` on the socket's timeout."""
    head = _recv_exact(sock, HEADER.size)
    _, length = _check_header(head)
    return decode(head + _recv_exact(sock, length + CRC.size))


# ---- secrets and login ----------------------------------------------------------------------------

def new_nonce():
    return os.urandom(NONCE_SIZE)


_ALPHABETS = [(set(string.digits), 10), (set(string.hexdigits.lower()), 16), (set(string.hexdigits.upper()), 16),
              (set(string.ascii_lowercase), 26), (set(string.ascii_lowercase + string.digits), 36),
              (set(string.ascii_letters), 52), (set(string.ascii_letters + string.digits), 62),
              (set(string.ascii_letters + string.digits + "+/=-_"), 64),
              (set(string.printable) - set("\t\n\r\x0b\x0c"), 95)]


def secret_bits(secret):
    r"""An estimate (an upper bound) of the entropy [bit] of a normalized ``secret`` (bytes): its length times
    :math:`\log_2` of the smallest usual alphabet that holds all its characters (digits 10, hex 16, lower case
    26, ..., base64 64, printable ASCII 95, any byte 256); 0 when it has fewer than 8 distinct bytes (a
    repeated pattern). ``head -c 32 /dev/urandom | base64`` gives 264."""
    if len(set(secret)) < min(8, len(secret)) or len(set(secret)) < 2:
        return 0.0
    chars = set(chr(b) for b in secret)
    size = next((n for alphabet, n in _ALPHABETS if chars <= alphabet), 256)
    return len(secret) * math.log2(size)


def secret_bytes(secret, source="the shared secret"):
    """The shared secret as the protocol uses it: UTF-8 bytes of ``secret`` (bytes or str) with leading and
    trailing whitespace removed (one rule for the board and the client, so a newline at the end of a secret
    file never matters). ProtocolError when it is empty or carries fewer than :data:`MIN_SECRET_BITS` bits
    (estimated by :func:`secret_bits`), with the command that makes a good one."""
    if secret is None:
        secret = b""
    if isinstance(secret, str):
        secret = secret.encode()
    secret = bytes(secret).strip()
    if not secret:
        raise ProtocolError(f"{source} is empty: make one with `{MAKE_SECRET}` (mode 600), give it to the board "
                            "(--secret-file FILE) and the same to Board.connect(url, secret_file=FILE)")
    bits = secret_bits(secret)
    if bits < MIN_SECRET_BITS:
        raise ProtocolError(f"{source} is too weak: about {bits:.0f} bits of entropy, at least {MIN_SECRET_BITS} "
                            f"(16 random bytes) are needed; make one with `{MAKE_SECRET}`")
    return secret


def read_secret_file(path):
    """:func:`secret_bytes` of the content of the file ``path``; ProtocolError naming the file when it is
    missing, unreadable, empty or too weak."""
    try:
        with open(path, "rb") as f:
            data = f.read()
    except FileNotFoundError:
        make = MAKE_SECRET.replace("FILE", str(path))
        raise ProtocolError(f"secret file {path} does not exist: make one with `{make}` "
                            f"and `chmod 600 {path}`") from None
    except OSError as e:
        raise ProtocolError(f"cannot read the secret file {path}: {e.strerror}; the board's user must be able "
                            "to read it (chown it to that user, mode 600)") from None
    return secret_bytes(data, source=f"the secret in {path}")


def _mac(key, data):
    return hmac.new(key, data, hashlib.sha256).digest()


def client_proof(secret, server_nonce, client_nonce):
    """HMAC-SHA256(secret, b"soro-client" | Ns | Nc): what the client sends to prove it knows the secret."""
    return _mac(secret_bytes(secret), b"soro-client" + server_nonce + client_nonce)


def server_proof(secret, server_nonce, client_nonce):
    """HMAC-SHA256(secret, b"soro-server" | Nc | Ns): the board's proof back to the client."""
    return _mac(secret_bytes(secret), b"soro-server" + client_nonce + server_nonce)


_SEQ64 = struct.Struct("<Q")


class Session:
    """Seals and opens the frames of one logged-in connection (see the module docstring).

    Parameters
    ----------
    secret : bytes or str
        The shared secret.
    server_nonce, client_nonce : bytes
        The nonces of the handshake (HELLO's Ns, AUTH's Nc).
    role : {"client", "board"}
        Which end this is: it sends with its own direction key and opens with the other.
    """

    def __init__(self, secret, server_nonce, client_nonce, role):
        if role not in ("client", "board"):
            raise ValueError(f"role must be 'client' or 'board', got {role!r}")
        key = _mac(secret_bytes(secret), b"soro-session" + bytes(server_nonce) + bytes(client_nonce))
        up, down = _mac(key, b"client->board"), _mac(key, b"board->client")
        self._send_key, self._recv_key = (up, down) if role == "client" else (down, up)
        self.sent = 0           # sequence number of the last frame sealed
        self.received = 0       # sequence number of the last frame opened

    def seal(self, mtype, body=b""):
        """The frame (bytes) of type ``mtype`` carrying ``body``, with the next sequence number and its MAC."""
        self.sent += 1
        inner = _SEQ64.pack(self.sent) + bytes(body)
        head = HEADER.pack(MAGIC, PROTOCOL_VERSION, int(MessageType(mtype)), len(inner) + MAC_SIZE)
        return encode(mtype, inner + _mac(self._send_key, head + inner))

    def open(self, mtype, payload):
        """The body of a sealed frame ``(mtype, payload)`` (as :func:`decode` returns it). ProtocolError when
        the MAC does not match (forged or altered on the path) or the sequence number is not the next one
        (replayed, reordered or dropped frame)."""
        if len(payload) < _SEQ64.size + MAC_SIZE:
            raise ProtocolError(f"{MessageType(mtype).name} frame of {len(payload)} payload bytes has no MAC: "
                                "after login every frame is sealed")
        inner, tag = payload[:-MAC_SIZE], payload[-MAC_SIZE:]
        head = HEADER.pack(MAGIC, PROTOCOL_VERSION, int(mtype), len(payload))
        if not hmac.compare_digest(tag, _mac(self._recv_key, head + inner)):
            raise ProtocolError(f"bad MAC on a {MessageType(mtype).name} frame: forged or altered on the path")
        (seq,) = _SEQ64.unpack_from(inner)
        if seq != self.received + 1:
            raise ProtocolError(f"sequence number {seq} on a {MessageType(mtype).name} frame, expected "
                                f"{self.received + 1}: a replayed, reordered or dropped frame")
        self.received = seq
        return inner[_SEQ64.size:]


def pack_auth(client_nonce, proof):
    return client_nonce + proof


def unpack_auth(payload):
    if len(payload) != NONCE_SIZE + 32:
        raise ProtocolError(f"AUTH payload of {len(payload)} bytes, expected {NONCE_SIZE + 32}")
    return payload[:NONCE_SIZE], payload[NONCE_SIZE:]


# ---- payloads -----------------------------------------------------------------------------------------
_HELLO = struct.Struct("<HHdd")     # version, channels, watchdog [s], board rate [Hz]


def pack_hello(h):
    n = int(h.channels)
    body = _HELLO.pack(h.version, n, h.watchdog, h.board_rate)
    arrays = np.concatenate([np.asarray(a, "<f8").reshape(n) for a in (h.p_min, h.p_max, h.rate)])
    return body + arrays.tobytes() + h.nonce


def unpack_hello(payload):
    if len(payload) < _HELLO.size + NONCE_SIZE:
        raise ProtocolError("HELLO payload too short")
    version, n, watchdog, rate = _HELLO.unpack_from(payload)
    if not 1 <= n <= MAX_CHANNELS or len(payload) != _HELLO.size + 24 * n + NONCE_SIZE:
        raise ProtocolError(f"HELLO payload of {len(payload)} bytes does not match {n} channels")
    a = np.frombuffer(payload, "<f8", 3 * n, _HELLO.size).reshape(3, n).astype(float)
    return Hello(version, n, watchdog, rate, a[0], a[1], a[2], payload[-NONCE_SIZE:])


_SEQ = struct.Struct("<I")


def pack_pressures(sequence, values):
    """SET payload: uint32 sequence number, then n float64 set-points [Pa]."""
    return _SEQ.pack(sequence & 0xFFFFFFFF) + np.asarray(values, "<f8").tobytes()


def unpack_pressures(payload, channels):
    if len(payload) != _SEQ.size + 8 * channels:
        raise ProtocolError(f"SET payload of {len(payload)} bytes; {channels} channels need "
                            f"{_SEQ.size + 8 * channels}")
    (seq,) = _SEQ.unpack_from(payload)
    return seq, np.frombuffer(payload, "<f8", channels, _SEQ.size).astype(float)


def pack_sequence(sequence):
    """READ/HEARTBEAT/VENT payload: the uint32 sequence number echoed by the STATE answer."""
    return _SEQ.pack(sequence & 0xFFFFFFFF)


def unpack_sequence(payload):
    if len(payload) != _SEQ.size:
        raise ProtocolError(f"payload of {len(payload)} bytes, expected a {_SEQ.size}-byte sequence number")
    return _SEQ.unpack(payload)[0]


_STATE = struct.Struct("<dIHH")     # time, sequence, channels, sensors


def pack_state(s):
    n, m = len(s.requested), len(s.sensors)
    return (_STATE.pack(s.time, s.sequence & 0xFFFFFFFF, n, m)
            + np.concatenate([s.requested, s.applied, s.measured]).astype("<f8").tobytes()
            + np.asarray(s.flags, "<u2").tobytes() + np.asarray(s.sensors, "<f8").tobytes())


def unpack_state(payload):
    if len(payload) < _STATE.size:
        raise ProtocolError("STATE payload too short")
    t, seq, n, m = _STATE.unpack_from(payload)
    if len(payload) != _STATE.size + 26 * n + 8 * m:
        raise ProtocolError(f"STATE payload of {len(payload)} bytes does not match {n} channels, {m} sensors")
    off = _STATE.size
    a = np.frombuffer(payload, "<f8", 3 * n, off).reshape(3, n).astype(float)
    off += 24 * n
    flags = np.frombuffer(payload, "<u2", n, off).astype(np.int64)
    sensors = np.frombuffer(payload, "<f8", m, off + 2 * n).astype(float)
    return State(t, seq, a[0], a[1], a[2], flags, sensors)


_ERROR = struct.Struct("<H")


def pack_error(code, message):
    return _ERROR.pack(int(code)) + message.encode()[:MAX_PAYLOAD - _ERROR.size]


def unpack_error(payload):
    if len(payload) < _ERROR.size:
        raise ProtocolError("ERROR payload too short")
    (code,) = _ERROR.unpack_from(payload)
    return code, payload[_ERROR.size:].decode(errors="replace")
