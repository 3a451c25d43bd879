"""The board's wire protocol: round trips, and every defect of a frame rejected with a ProtocolError."""
import struct
import zlib

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sorocontrol import protocol as P
from sorofem.errors import ProtocolError


def test_frame_round_trip_every_type():
    for mtype in P.MessageType:
        payload = bytes(range(int(mtype) * 7 % 50))
        assert P.decode(P.encode(mtype, payload)) == (mtype, payload)


def test_frame_layout_is_the_documented_one():
    frame = P.encode(P.MessageType.SET, b"\x01\x02")
    assert frame[:2] == b"SB" and frame[2] == P.PROTOCOL_VERSION and frame[3] == P.MessageType.SET
    assert struct.unpack("<I", frame[4:8])[0] == 2 and frame[8:10] == b"\x01\x02"
    assert struct.unpack("<I", frame[10:])[0] == zlib.crc32(frame[:10])


def test_payload_round_trips():
    rng = np.random.default_rng(0)
    n = 12
    hello = P.Hello(1, n, 0.5, 400.0, -rng.random(n) * 1e5, rng.random(n) * 1e5, rng.random(n) * 1e6,
                    P.new_nonce())
    back = P.unpack_hello(P.pack_hello(hello))
    assert back.channels == n and back.watchdog == 0.5 and back.board_rate == 400.0 and back.nonce == hello.nonce
    for a, b in ((hello.p_min, back.p_min), (hello.p_max, back.p_max), (hello.rate, back.rate)):
        np.testing.assert_array_equal(a, b)
    values = rng.normal(size=n) * 1e4
    seq, v = P.unpack_pressures(P.pack_pressures(2**32 + 5, values), n)
    assert seq == 5 and np.array_equal(v, values)   # the sequence number wraps at 32 bits
    state = P.State(12.5, 7, values, values / 2, values / 3, np.arange(n) % 16, rng.random(4))
    s2 = P.unpack_state(P.pack_state(state))
    assert (s2.time, s2.sequence) == (12.5, 7)
    for f in ("requested", "applied", "measured", "flags", "sensors"):
        np.testing.assert_array_equal(getattr(s2, f), getattr(state, f))
    assert P.unpack_error(P.pack_error(P.ErrorCode.BUSY, "busy")) == (P.ErrorCode.BUSY, "busy")
    assert P.unpack_sequence(P.pack_sequence(9)) == 9


SECRET = "4f0c2a9d51e6b7384c2d9a0f6e1b5c73"      # 32 hex digits: 128 bits
OTHER = "9b1e4c7a2f5d8036e1c4b7a9d2f50c68"


def test_login_proofs_depend_on_secret_and_both_nonces():
    ns, nc = P.new_nonce(), P.new_nonce()
    proof = P.client_proof(SECRET, ns, nc)
    assert proof == P.client_proof(SECRET.encode(), ns, nc)
    assert proof != P.client_proof(OTHER, ns, nc) != P.client_proof(SECRET, P.new_nonce(), nc)
    assert P.server_proof(SECRET, ns, nc) != proof   # the two directions differ: no reflection
    with pytest.raises(ProtocolError, match="empty"):
        P.client_proof("", ns, nc)


def test_secrets_one_whitespace_rule_and_a_minimum_entropy(tmp_path):
    """Whitespace at both ends never matters, on either side; secrets under 128 bits are refused with the
    command that makes a good one; missing and empty files say so."""
    assert P.secret_bytes(f"  {SECRET}\n") == P.secret_bytes(SECRET.encode()) == SECRET.encode()
    ns, nc = P.new_nonce(), P.new_nonce()
    assert P.client_proof(SECRET + "\n", ns, nc) == P.client_proof(" " + SECRET, ns, nc)
    for weak in ("x", "s3cret", "0123456789abcdef", "ab" * 40, "password1234"):
        with pytest.raises(ProtocolError, match="too weak.*urandom"):
            P.secret_bytes(weak)
    # the estimate: length x log2(alphabet): 32 hex digits = 128 bits, 20 printable = 131, base64 of 32 bytes
    assert P.secret_bits(SECRET.encode()) == pytest.approx(128.0)
    assert P.secret_bits(b"Tr0ub4dor&3-horse!?x") == pytest.approx(20 * np.log2(95))
    assert P.secret_bits(b"ab" * 40) == 0.0
    f = tmp_path / "secret"
    with pytest.raises(ProtocolError, match="does not exist.*urandom"):
        P.read_secret_file(f)
    f.write_text("\n")
    with pytest.raises(ProtocolError, match="empty"):
        P.read_secret_file(f)
    f.write_text(SECRET + "\n")
    assert P.read_secret_file(f) == SECRET.encode()


def test_session_seals_and_opens_and_refuses_forgery_replay_and_reordering():
    ns, nc = P.new_nonce(), P.new_nonce()
    client, board = P.Session(SECRET, ns, nc, "client"), P.Session(SECRET, ns, nc, "board")
    frames = [client.seal(P.MessageType.SET, P.pack_pressures(k, [k * 1e3, 0.0])) for k in range(1, 4)]
    assert P.decode(frames[0])[1] != P.decode(frames[1])[1]
    assert board.open(*P.decode(frames[0])) == P.pack_pressures(1, [1e3, 0.0])
    with pytest.raises(ProtocolError, match="sequence number 1 .* expected 2"):      # replay
        board.open(*P.decode(frames[0]))
    with pytest.raises(ProtocolError, match="sequence number 3 .* expected 2"):      # reordered (or dropped)
        board.open(*P.decode(frames[2]))
    body = bytearray(P.decode(frames[1])[1])
    body[8 + 4 + 7] ^= 0x40                       # the first set-point's exponent: 2 kPa becomes ~1e22 Pa
    forged = P.encode(P.MessageType.SET, bytes(body))
    with pytest.raises(ProtocolError, match="bad MAC"):                               # valid CRC, bad MAC
        board.open(*P.decode(forged))
    retyped = P.encode(P.MessageType.VENT, P.decode(frames[1])[1])                   # header is authenticated
    with pytest.raises(ProtocolError, match="bad MAC"):
        board.open(*P.decode(retyped))
    assert board.open(*P.decode(frames[1])) == P.pack_pressures(2, [2e3, 0.0])       # the real one still opens
    reflected = board.seal(P.MessageType.SET, P.pack_pressures(9, [0.0, 0.0]))        # keys differ per direction
    with pytest.raises(ProtocolError, match="bad MAC"):
        P.Session(SECRET, ns, nc, "board").open(*P.decode(reflected))
    with pytest.raises(ProtocolError, match="bad MAC"):                               # other session, same secret
        P.Session(SECRET, P.new_nonce(), nc, "board").open(*P.decode(frames[2]))
    with pytest.raises(ProtocolError, match="no MAC"):
        board.open(P.MessageType.READ, P.pack_sequence(1))
    assert client.open(*P.decode(reflected)) == P.pack_pressures(9, [0.0, 0.0])     # board -> client works
    assert client.open(*P.decode(board.seal(P.MessageType.STATE, b"abc"))) == b"abc"


@pytest.mark.parametrize("defect,match", [
    (lambda f: f[:5], "truncated"),
    (lambda f: f[:-1], "header announces"),
    (lambda f: f + b"\x00", "header announces"),
    (lambda f: b"XX" + f[2:], "magic"),
    (lambda f: f[:2] + bytes([P.PROTOCOL_VERSION + 1]) + f[3:], "version"),
    (lambda f: f[:3] + b"\xee" + f[4:], "unknown message type"),
    (lambda f: f[:4] + struct.pack("<I", P.MAX_PAYLOAD + 1) + f[8:], "MAX_PAYLOAD"),
    (lambda f: f[:9] + bytes([f[9] ^ 0x40]) + f[10:], "checksum"),
])
def test_defective_frames_are_rejected(defect, match):
    frame = P.encode(P.MessageType.SET, P.pack_pressures(1, [1.0, 2.0]))
    with pytest.raises(ProtocolError, match=match):
        P.decode(defect(frame))


def test_wrong_payload_sizes_are_rejected():
    with pytest.raises(ProtocolError, match="channels need"):
        P.unpack_pressures(P.pack_pressures(1, [1.0, 2.0]), 3)
    with pytest.raises(ProtocolError):
        P.unpack_state(b"\x00" * 10)
    with pytest.raises(ProtocolError):
        P.unpack_hello(b"\x00" * 40)
    with pytest.raises(ProtocolError):
        P.unpack_auth(b"\x00" * 10)


def test_frame_reader_reassembles_a_stream_fed_byte_by_byte():
    frames = [P.encode(t, bytes([i]) * i) for i, t in enumerate(P.MessageType)]
    reader, got = P.FrameReader(), []
    for byte in b"".join(frames):
        got += reader.feed(bytes([byte]))
    assert got == [P.decode(f) for f in frames] and reader.pending == 0


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.binary(max_size=64))
def test_fuzz_random_bytes_only_ever_raise_protocol_error(data):
    for fn in (P.decode, P.FrameReader().feed, P.unpack_state, P.unpack_hello, P.unpack_error):
        try:
            fn(data)
        except ProtocolError:
            pass


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 8 * 60 - 1), st.integers(1, 255))
def test_fuzz_every_corruption_of_a_valid_frame_is_caught(bit, xor):
    frame = bytearray(P.encode(P.MessageType.SET, P.pack_pressures(3, np.linspace(-1e4, 1e4, 6))))
    frame[(bit // 8) % len(frame)] ^= xor
    with pytest.raises(ProtocolError):
        P.decode(bytes(frame))
