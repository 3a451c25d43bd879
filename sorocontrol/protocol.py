"""The board's wire protocol: versioned, checksummed binary frames over TCP, with challenge-response login.

The specification, for implementers of other clients, is ``docs/board-protocol.md``; this module is its
reference implementation, shared by the board server (:mod:`sorocontrol.server`) and the host client
(:class:`sorocontrol.Board`).

Frame (all integers little-endian)::

    offset  size  field
    0       2     magic b"SB"
    2       1     protocol version (PROTOCOL_VERSION = 1)
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

The secret never crosses the wire; a replayed AUTH fails because Ns is fresh per connection. Pressures are
gauge pressures in pascal (float64). See the spec for the payload layouts.
"""
import enum
import hashlib
import hmac
import os
import struct
import zlib
from dataclasses import dataclass, field

import numpy as np

from sorofem.errors import ProtocolError

__all__ = ["PROTOCOL_VERSION", "MAGIC", "MAX_PAYLOAD", "MAX_CHANNELS", "HEADER", "MessageType", "Flag",
           "Hello", "State", "encode", "decode", "read_frame", "FrameReader", "client_proof", "server_proof",
           "new_nonce", "pack_hello", "unpack_hello", "pack_pressures", "unpack_pressures", "pack_state",
           "unpack_state", "pack_error", "unpack_error"]

PROTOCOL_VERSION = 1
MAGIC = b"SB"
MAX_PAYLOAD = 4096      # bytes; the largest legal payload (HELLO with 64 channels) is < 1.2 kB
MAX_CHANNELS = 64
NONCE_SIZE = 32
HEADER = struct.Struct("<2sBBI")        # magic, version, type, payload length
CRC = struct.Struct("<I")


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


def read_frame(sock):
    """Block until one frame arrives on ``sock``; ``(type, payload)``. ProtocolError on a defect,
    ConnectionError when the peer closes, ``socket.timeout`` on the socket's timeout."""
    head = _recv_exact(sock, HEADER.size)
    _, length = _check_header(head)
    return decode(head + _recv_exact(sock, length + CRC.size))


# ---- login --------------------------------------------------------------------------------------------

def new_nonce():
    return os.urandom(NONCE_SIZE)


def _secret(secret):
    if isinstance(secret, str):
        secret = secret.encode()
    if not secret:
        raise ProtocolError("empty shared secret: set one on the board (--secret-file) and pass the same to "
                            "Board.connect(url, secret=...)")
    return bytes(secret)


def client_proof(secret, server_nonce, client_nonce):
    """HMAC-SHA256(secret, b"soro-client" | Ns | Nc): what the client sends to prove it knows the secret."""
    return hmac.new(_secret(secret), b"soro-client" + server_nonce + client_nonce, hashlib.sha256).digest()


def server_proof(secret, server_nonce, client_nonce):
    """HMAC-SHA256(secret, b"soro-server" | Nc | Ns): the board's proof back to the client."""
    return hmac.new(_secret(secret), b"soro-server" + client_nonce + server_nonce, hashlib.sha256).digest()


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
