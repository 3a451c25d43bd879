"""Board server and client: login, limits, watchdog, one client at a time, robustness to bad peers, the
simulated plant against its closed-form step response, and the real-time loop.

No test asserts elapsed time or an achieved rate: behaviour that depends on time runs on an injected clock
with the board loop stepped by the test (:meth:`BoardServer.tick`), and waits on real time are deadlines
generous enough for a loaded machine (the figures are in tests/benchmarks/bench_board.py)."""
import os
import signal
import socket
import subprocess
import sys
import textwrap
import threading
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sorocontrol import Board, BoardServer, MockDriver, SimulatedPlant
from sorocontrol import protocol as P
from sorofem.errors import ParameterError, ProtocolError

SECRET = "correct horse battery staple"
WRONG = "correct horse battery stable"
DEADLINE = 10.0      # [s] for waits on real time: generous, the suite must pass on a loaded machine


@pytest.fixture
def server():
    srv = BoardServer(MockDriver(3), SECRET, port=0, watchdog=0.3, rate=200e3, p_min=-50e3, p_max=80e3).start()
    yield srv
    srv.stop()


@pytest.fixture
def patient():
    """The ``server`` with a watchdog of DEADLINE: for raw clients that send no heartbeats between their
    frames (the 0.3 s watchdog dropped them at load 20 before the frame under test arrived)."""
    srv = BoardServer(MockDriver(3), SECRET, port=0, watchdog=DEADLINE, rate=200e3, p_min=-50e3,
                      p_max=80e3).start()
    yield srv
    srv.stop()


class Clock:
    """An injected board clock [s] that only moves when the test says so."""

    def __init__(self):
        self.t = 1000.0

    def __call__(self):
        return self.t

    def advance(self, dt):
        self.t += dt


@pytest.fixture
def stepped():
    """A server whose board loop is stepped by the test (``srv.tick()``) on an injected clock."""
    clock = Clock()
    srv = BoardServer(MockDriver(3), SECRET, port=0, watchdog=0.3, rate=200e3, p_min=-50e3, p_max=80e3,
                      board_rate=100.0, clock=clock).start(loop=False)
    srv.clock = clock
    yield srv
    srv.stop()


def url(srv):
    return f"tcp://127.0.0.1:{srv.address[1]}"


def wait_until(cond, timeout=DEADLINE):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if cond():
            return time.monotonic() - t0
        time.sleep(0.002)
    raise AssertionError("condition not reached")


def reader_idle(srv):
    """Wait until the thread that serves the client has answered it (the client may see the answer first): the
    watchdog counts only the silence of a client whose frames are all served."""
    wait_until(lambda: not srv.serving)


def raw_login(srv, secret=SECRET):
    """Log in by hand: ``(socket, session, (type, body) of the answer to AUTH)``."""
    sock = socket.create_connection(srv.address, timeout=DEADLINE)
    mtype, payload = P.read_frame(sock)
    hello = P.unpack_hello(payload)
    nc = P.new_nonce()
    P.send_frame(sock, P.encode(P.MessageType.AUTH, P.pack_auth(nc, P.client_proof(secret, hello.nonce, nc))))
    return sock, P.Session(secret, hello.nonce, nc, "client"), P.read_frame(sock)


def sealed_answer(sock, session):
    mtype, payload = P.read_frame(sock)
    return mtype, session.open(mtype, payload)


def test_login_announces_limits_and_commands_answer_with_state(server):
    with Board.connect(url(server), secret=SECRET) as brd:
        assert brd.channels == 3 and brd.watchdog == 0.3
        np.testing.assert_array_equal(brd.p_max, 80e3)
        s = brd.set_pressure([10e3, -5e3, 0.0])
        np.testing.assert_array_equal(s.requested, [10e3, -5e3, 0.0])
        assert brd.read().sequence == s.sequence + 1 >= 2   # (the keepalive may have sent 1 under load)
        wait_until(lambda: np.allclose(brd.read().measured, [10e3, -5e3, 0.0]))
        s = brd.vent()
        assert np.all(s.applied == 0) and s.flagged(P.Flag.VENTED).size == 3
    assert np.all(server.driver.value == 0)  # closing vents


def test_limits_clamp_and_are_reported(server):
    with Board.connect(url(server), secret=SECRET) as brd:
        s = brd.set_pressure([500e3, -500e3, 20e3])
        np.testing.assert_array_equal(s.requested, [80e3, -50e3, 20e3])
        assert s.flagged(P.Flag.CLAMPED).tolist() == [0, 1]
        assert brd.set_pressure(0.0).flagged(P.Flag.CLAMPED).size == 0
        with pytest.raises(ParameterError, match="non-finite"):
            brd.set_pressure([np.nan, 0, 0])
        with pytest.raises(ParameterError, match="3 values"):
            brd.set_pressure([1.0, 2.0])


def test_rate_limit_slews_the_applied_pressure(stepped):
    """Stepped board loop (100 Hz on the injected clock): the applied set-point rises by exactly rate * dt
    = 200 kPa/s * 10 ms = 2 kPa per tick, flagged RATE_LIMITED until it reaches the request."""
    srv = stepped
    with Board.connect(url(srv), secret=SECRET, keepalive=False) as brd:
        brd.set_pressure([80e3, 0, 0])
        applied, limited = [], []
        for _ in range(45):
            srv.clock.advance(0.01)
            srv.tick()
            s = brd.read()              # also feeds the watchdog (0.3 s of board time)
            applied.append(s.applied[0])
            limited.append(bool(s.flags[0] & P.Flag.RATE_LIMITED))
        applied = np.array(applied)
        np.testing.assert_allclose(applied[:40], 2e3 * np.arange(1, 41), rtol=1e-12)
        assert np.all(applied[40:] == 80e3) and srv.driver.value[0] == 80e3
        assert all(limited[:39]) and not any(limited[39:])
        srv.tick()
        assert np.all(srv.driver.value[1:] == 0)


def test_second_client_is_refused(server):
    with Board.connect(url(server), secret=SECRET) as brd:
        with pytest.raises(ProtocolError, match="BUSY"):
            Board.connect(url(server), secret=SECRET)
        brd.set_pressure([1e3, 0, 0])   # the first client keeps control
    with Board.connect(url(server), secret=SECRET) as brd:   # free again after the first left
        assert brd.read().sequence == 1


def test_a_client_of_another_protocol_version_is_told_so(server):
    sock = socket.create_connection(server.address, timeout=2.0)
    P.read_frame(sock)   # HELLO
    frame = bytearray(P.encode(P.MessageType.AUTH, b"\x00" * 64))
    frame[2] = P.PROTOCOL_VERSION + 1
    P.send_frame(sock, bytes(frame))
    mtype, payload = P.read_frame(sock)
    assert mtype == P.MessageType.ERROR and P.unpack_error(payload)[0] == P.ErrorCode.VERSION
    sock.close()


def test_bad_secret_is_refused_and_the_server_goes_on(server):
    with pytest.raises(ProtocolError, match="AUTH.*wrong shared secret"):
        Board.connect(url(server), secret=WRONG)
    assert any("authentication failed" in e for _, e in server.events)
    brd = None

    def login():
        nonlocal brd
        try:
            brd = Board.connect(url(server), secret=SECRET)
        except ProtocolError as e:
            assert "retry in" in str(e)     # the backoff after the failure (0.1 s), nothing else
            return False
        return True
    wait_until(login)
    with brd:
        assert brd.read() is not None


def test_failed_logins_back_off_per_address(stepped):
    """After the k-th failure in a row from an address its next attempts are refused, without checking a
    secret, for 0.1 s * 2**(k-1) (capped at 10 s) of the board clock; a success resets the count."""
    srv = stepped
    for k in range(1, 9):
        with pytest.raises(ProtocolError, match="AUTH.*wrong shared secret"):
            Board.connect(url(srv), secret=WRONG)
        wait = min(0.1 * 2 ** (k - 1), 10.0)
        checked = srv.counters["auth_failures"]
        with pytest.raises(ProtocolError, match=f"retry in {wait:.1f} s"):
            Board.connect(url(srv), secret=SECRET)          # even the right secret waits
        srv.clock.advance(wait * 0.99)
        with pytest.raises(ProtocolError, match="retry in"):
            Board.connect(url(srv), secret=WRONG)
        assert srv.counters["auth_failures"] == checked == k   # refused attempts check no secret
        srv.clock.advance(wait * 0.02)
    assert srv.counters["backoff_refusals"] == 16
    for k in range(9, 2000):           # a long attack: the wait stays at its cap (no overflow of 2**k)
        srv.clock.advance(10.0)
        with pytest.raises(ProtocolError, match="wrong shared secret"):
            Board.connect(url(srv), secret=WRONG)
    with pytest.raises(ProtocolError, match="retry in 10.0 s"):
        Board.connect(url(srv), secret=WRONG)
    srv.clock.advance(10.0)
    with Board.connect(url(srv), secret=SECRET, keepalive=False) as brd:
        brd.read()
    with pytest.raises(ProtocolError, match="wrong shared secret"):
        Board.connect(url(srv), secret=WRONG)
    with pytest.raises(ProtocolError, match="retry in 0.1 s"):     # the count restarted after the success
        Board.connect(url(srv), secret=WRONG)


def test_each_pending_login_has_its_own_deadline_not_the_watchdog(stepped):
    """A connection has auth_timeout (2 s of board time) to log in, however long the watchdog (0.3 s): AUTH
    after 1.5 s is accepted; after 2.1 s the board has answered ERROR auth and closed."""
    srv = stepped
    late = socket.create_connection(srv.address, timeout=DEADLINE)
    hello = P.unpack_hello(P.read_frame(late)[1])
    slow = socket.create_connection(srv.address, timeout=DEADLINE)
    hello_slow = P.unpack_hello(P.read_frame(slow)[1])
    srv.clock.advance(1.5)
    nc = P.new_nonce()
    P.send_frame(slow, P.encode(P.MessageType.AUTH, P.pack_auth(nc, P.client_proof(SECRET, hello_slow.nonce, nc))))
    assert P.read_frame(slow)[0] == P.MessageType.READY
    srv.clock.advance(0.6)
    mtype, payload = P.read_frame(late)          # the accept loop expires it within its 50 ms poll
    assert mtype == P.MessageType.ERROR and "no AUTH within 2.0 s" in P.unpack_error(payload)[1]
    assert srv.counters["expired"] == 1 and hello.nonce != hello_slow.nonce
    late.close()
    slow.close()


def test_client_checks_the_board_knows_the_secret():
    """A fake board that answers READY without knowing the secret is detected (mutual authentication)."""
    lst = socket.create_server(("127.0.0.1", 0))

    def fake():
        conn, _ = lst.accept()
        P.send_frame(conn, P.encode(P.MessageType.HELLO, P.pack_hello(
            P.Hello(1, 1, 0.5, 400.0, [-1.0], [1.0], [1.0], P.new_nonce()))))
        P.read_frame(conn)
        P.send_frame(conn, P.encode(P.MessageType.READY, b"\x00" * 32))
        time.sleep(0.2)
        conn.close()
    import threading
    th = threading.Thread(target=fake)
    th.start()
    with pytest.raises(ProtocolError, match="could not prove"):
        Board.connect(f"tcp://127.0.0.1:{lst.getsockname()[1]}", secret=SECRET)
    th.join()
    lst.close()


def _garbage(name, session):
    """Bad frames after login (``session`` seals them like the real client would)."""
    if name == "text":
        return b"hello world\n"
    if name == "size":
        return session.seal(P.MessageType.SET, b"\x00" * 3)
    if name == "server_message":
        return session.seal(P.MessageType.HELLO, b"")
    if name == "non_finite":
        return session.seal(P.MessageType.SET, P.pack_pressures(1, [np.nan, 0, 0]))
    if name == "checksum":
        return session.seal(P.MessageType.READ, P.pack_sequence(1))[:-1] + b"\xff"
    raise KeyError(name)


@pytest.mark.parametrize("garbage", ["text", "size", "server_message", "non_finite", "checksum"])
def test_malformed_frames_after_login_vent_and_the_server_survives(patient, garbage):
    server = patient
    sock, session, (mtype, _) = raw_login(server)
    assert mtype == P.MessageType.READY
    P.send_frame(sock, session.seal(P.MessageType.SET, P.pack_pressures(1, [30e3, 0, 0])))
    sealed_answer(sock, session)
    P.send_frame(sock, _garbage(garbage, session))
    mtype, body = sealed_answer(sock, session)
    assert mtype == P.MessageType.ERROR, "the server answers a bad frame with ERROR"
    code, _ = P.unpack_error(body)
    assert code == (P.ErrorCode.UNEXPECTED if garbage == "server_message" else P.ErrorCode.MALFORMED)
    wait_until(lambda: server.client is None and np.all(server.requested == 0))
    sock.close()
    with Board.connect(url(server), secret=SECRET, keepalive=False) as brd:   # still serving
        assert brd.read().sequence == 1


def _injections(frames):
    """What a host on the path can do with the client's sealed frames ``frames`` (SET 30 kPa, SET 40 kPa,
    SET 50 kPa, each with the next sequence number), of which the first was delivered."""
    return {
        "bad_mac": _forge(frames[1]),   # a valid CRC, a forged set-point, the MAC left as it was
        "replayed": frames[0],      # the delivered frame again
        "reordered": frames[2],     # the third before the second
        "unsealed": P.encode(P.MessageType.SET, P.pack_pressures(2, [80e3, 0, 0])),   # a v1-style frame
    }


def _forge(frame):
    """``frame`` with its first set-point replaced by 80 kPa, CRC recomputed, MAC untouched."""
    payload = bytearray(P.decode(frame)[1])
    payload[8 + 4:8 + 12] = np.float64(80e3).tobytes()
    return P.encode(P.MessageType.SET, bytes(payload))


@pytest.mark.parametrize("attack", ["bad_mac", "replayed", "reordered", "unsealed"])
def test_injected_frames_are_refused_and_vent(patient, attack):
    """A frame with a valid CRC but a bad MAC, a replayed one, a reordered one, an unsealed one: ERROR
    INTEGRITY, the board vents and drops the connection."""
    server = patient
    sock, session, (mtype, _) = raw_login(server)
    assert mtype == P.MessageType.READY
    frames = [session.seal(P.MessageType.SET, P.pack_pressures(k + 1, [p, 0, 0]))
              for k, p in enumerate((30e3, 40e3, 50e3))]
    P.send_frame(sock, frames[0])
    assert sealed_answer(sock, session)[0] == P.MessageType.STATE
    wait_until(lambda: server.driver.value[0] == 30e3)
    P.send_frame(sock, _injections(frames)[attack])
    mtype, body = sealed_answer(sock, session)
    code, text = P.unpack_error(body)
    assert mtype == P.MessageType.ERROR
    assert code == P.ErrorCode.INTEGRITY, text
    assert ("MAC" in text) if attack in ("bad_mac", "unsealed") else ("sequence number" in text)
    wait_until(lambda: server.client is None and server.driver.value[0] == 0.0)
    assert np.all(server.requested == 0) and not any(w[0] == 80e3 for _, w in server.driver.writes)
    assert any("protocol error" in e for _, e in server.events) and any("vented" in e for _, e in server.events)
    with pytest.raises((ConnectionError, OSError, ProtocolError)):
        P.send_frame(sock, frames[1])
        sealed_answer(sock, session)
    sock.close()


@settings(max_examples=25, deadline=None)
@given(st.binary(min_size=1, max_size=300))
def test_fuzz_the_live_server_with_random_bytes(data):
    with BoardServer(MockDriver(2), SECRET, port=0, watchdog=0.3, auth_timeout=0.3) as srv:
        for logged_in in (False, True):
            if logged_in:
                sock, _, _ = raw_login(srv)
            else:
                sock = socket.create_connection(srv.address, timeout=2.0)
                P.read_frame(sock)   # HELLO
            P.send_frame(sock, data)
            sock.settimeout(1.0)
            try:
                while sock.recv(4096):
                    pass
            except (socket.timeout, ConnectionError):
                pass
            sock.close()
            wait_until(lambda: srv.client is None)
        with Board.connect(url(srv), secret=SECRET) as brd:
            assert brd.read() is not None


CLIENT = textwrap.dedent("""
    import sys, time
    from sorocontrol import Board
    strict = sys.argv[3] == "strict"
    brd = Board.connect(sys.argv[1], secret=sys.argv[2], keepalive=not strict)
    brd.set_pressure([40e3, 0, 0])
    print("ready", flush=True)
    while True:                       # strict: the program's own heartbeats; keepalive: a person at a prompt
        time.sleep(0.05 if strict else 10.0)
        if strict:
            brd.heartbeat()
""")


@pytest.mark.parametrize("mode", ["strict", "keepalive"])
@pytest.mark.parametrize("how", ["kill", "stop"])
def test_watchdog_vents_when_the_client_dies_or_hangs(server, how, mode):
    """SIGKILL: the kernel closes the socket, the server vents at once. SIGSTOP: the socket stays open and
    silent (the keepalive thread stops with the process); the watchdog (0.3 s) vents, and the board says
    so. The same whether the client heartbeats itself (strict) or by its keepalive thread."""
    proc = subprocess.Popen([sys.executable, "-c", CLIENT, url(server), SECRET, mode], stdout=subprocess.PIPE,
                            text=True, cwd=os.getcwd())
    try:
        assert proc.stdout.readline().strip() == "ready"
        wait_until(lambda: server.driver.value[0] > 39e3)
        if mode == "keepalive":       # the client program sleeps 10 s: only its keepalive holds the session
            time.sleep(3 * server.watchdog)
            assert server.client is not None and server.driver.value[0] == 40e3
        os.kill(proc.pid, signal.SIGKILL if how == "kill" else signal.SIGSTOP)
        wait_until(lambda: server.driver.value[0] == 0.0 and server.client is None
                   and any("vented" in e for _, e in server.events))
        if how == "stop":
            silent = [float(e.split(" for ")[1].split(" s")[0]) for _, e in server.events if "watchdog:" in e]
            assert silent and silent[-1] >= server.watchdog, "vented by the watchdog, not before its timeout"
    finally:
        proc.kill()
        proc.wait()
        proc.stdout.close()


@pytest.fixture
def sigpipe_recorder():
    """SIGPIPE caught and recorded, as a host library may catch it (PETSc's handler aborts the process)."""
    caught = []
    old = signal.signal(signal.SIGPIPE, lambda *a: caught.append(a[0]))
    yield caught
    signal.signal(signal.SIGPIPE, old)


def test_watchdog_vents_at_the_first_tick_past_its_timeout(stepped, sigpipe_recorder):
    """... and the client that was dropped gets ProtocolError on its next commands, never a SIGPIPE."""
    srv = stepped
    with Board.connect(url(srv), secret=SECRET, keepalive=False) as brd:
        brd.set_pressure([20e3, 0, 0])
        reader_idle(srv)
        for _ in range(30):                      # 0.30 s of board time: not yet (the timeout is > 0.3 s)
            srv.clock.advance(0.01)
            srv.tick()
        assert srv.client is not None and srv.driver.value[0] > 0
        srv.clock.advance(0.01)
        srv.tick()
        assert srv.client is None and np.all(srv.driver.value == 0) and np.all(srv.requested == 0)
        assert "watchdog" in srv.events[-2][1] and srv.events[-1][1] == "vented (watchdog)"
        with pytest.raises(ProtocolError, match=r"WATCHDOG: watchdog: no valid command .* for 0\.310 s"):
            brd.read()                           # the board said why before closing
        for _ in range(3):
            with pytest.raises(ProtocolError, match="lost: board refused: WATCHDOG"):
                brd.read()
    assert sigpipe_recorder == []


def test_watchdog_counts_the_clients_silence_not_the_servers(stepped):
    """Frames that reached the board but wait unread (the thread that serves the client could not run: held
    here by the test) are the client speaking: past the watchdog the board waits for them, and keeps the
    pressure; past the hard limit (max(4 x 0.3, 0.3 + 1) = 1.3 s) the server is stuck: it drops the client,
    vents and says so. The frames left unread are never carried out."""
    srv = stepped
    sock, session, (mtype, _) = raw_login(srv)
    assert mtype == P.MessageType.READY
    P.send_frame(sock, session.seal(P.MessageType.SET, P.pack_pressures(1, [20e3, 0, 0])))
    assert sealed_answer(sock, session)[0] == P.MessageType.STATE
    srv.tick()
    reader_idle(srv)
    reading = srv._client_reading
    with reading:                                # the server's reader cannot run
        P.send_frame(sock, session.seal(P.MessageType.HEARTBEAT, P.pack_sequence(2)))
        wait_until(lambda: srv._readable(srv._client))
        for _ in range(100):                     # 1.00 s > the watchdog: the heartbeat waits unread
            srv.clock.advance(0.01)
            srv.tick()
        assert srv.client is not None and srv.driver.value[0] == 20e3
        assert srv.counters["watchdog_waits"] == 70   # every tick from 0.31 s on
        for _ in range(31):                      # 1.31 s: past the hard limit
            srv.clock.advance(0.01)
            srv.tick()
        assert srv.client is None and np.all(srv.driver.value == 0)
        assert "were not read for 1.310 s (hard limit 1.3 s): the board server is overloaded or stuck" in \
            srv.events[-2][1] and srv.events[-1][1] == "vented (watchdog)"
    sock.settimeout(DEADLINE)
    try:                                         # the connection is closed; the heartbeat is never carried out
        assert sock.recv(4096) == b""
    except ConnectionResetError:
        pass
    sock.close()
    assert srv.requested[0] == 0 and srv.counters["late_commands"] == 0


STALL_CLIENT = textwrap.dedent("""
    import sys, time
    from sorocontrol import Board
    from sorofem.errors import ProtocolError
    brd = Board.connect(sys.argv[1], secret=sys.argv[2], keepalive=False, timeout=30.0)
    try:
        for k in range(150):             # 3 s at 50 Hz; the jump to 40 kPa after 0.5 s stalls the board
            brd.set_pressure([40e3 if k >= 25 else 0.0])
            time.sleep(0.02)
        print("kept", brd.read().requested[0], flush=True)
    except ProtocolError as e:
        print("lost", e, flush=True)
""")


def test_watchdog_counts_from_the_answer_not_the_arrival(stepped):
    """A command that the server was slow to answer (0.8 s between its arrival and the answer, > the 0.3 s
    watchdog: the board loop held the interpreter in between) leaves the client its whole watchdog after the
    answer: it waited for that answer before sending again. (Counted from the arrival, the first tick after the
    answer dropped it: the intermittent 'no valid command for 0.801 s' of the stalled-board test on a busy
    machine.) A client that then stays silent is still vented at the first tick past the watchdog."""
    srv = stepped
    slow = srv._command

    def answered_late(*a, **kw):
        out = slow(*a, **kw)
        srv.clock.advance(0.8)
        return out
    srv._command = answered_late
    with Board.connect(url(srv), secret=SECRET, keepalive=False) as brd:
        brd.set_pressure([20e3, 0, 0])
        reader_idle(srv)
        srv._command = slow
        for _ in range(30):                      # 0.30 s after the answer: kept
            srv.clock.advance(0.01)
            srv.tick()
        assert srv.client is not None and srv.driver.value[0] > 0
        srv.clock.advance(0.01)
        srv.tick()                               # 0.31 s of silence after the answer: vented
        assert srv.client is None and np.all(srv.driver.value == 0)
        assert "no valid command" in srv.events[-2][1] and "0.310 s" in srv.events[-2][1]


def test_a_board_loop_stalled_past_the_watchdog_keeps_a_healthy_client(tmp_path):
    """The intermittent drop of the simulated board after a pressure jump, made deterministic: the driver's
    step after the jump holds the interpreter for 0.8 s (> the 0.3 s watchdog), as the simulated beam's
    compiled step did on a loaded machine, while a client in another process goes on commanding at 50 Hz.
    Its frames wait in the socket; the server reads them after the stall and the client keeps the board (a
    server measuring its own silence dropped it at the first tick after the stall: "lost the board: Broken
    pipe"; counters["watchdog_waits"] counts the ticks that found the frames still unread, 0 when the reader
    ran first)."""
    import ctypes

    class Stalling(MockDriver):
        stalled = False

        def apply(self, setpoints, t):
            if not self.stalled and setpoints[0] > 0:
                self.stalled = True
                ctypes.PyDLL(None).usleep(800_000)     # holds the GIL, as a numba kernel without nogil
            return super().apply(setpoints, t)
    drv = Stalling(1)
    with BoardServer(drv, SECRET, port=0, watchdog=0.3) as srv:
        proc = subprocess.run([sys.executable, "-c", STALL_CLIENT, url(srv), SECRET], capture_output=True,
                              text=True, cwd=os.getcwd(), timeout=120)
        assert drv.stalled, "the stall happened"
        assert proc.stdout.strip() == "kept 40000.0", proc.stdout + proc.stderr[-2000:]
        assert not any("watchdog" in e for _, e in srv.events)


def test_no_client_means_zero_pressure_at_every_tick(stepped):
    """Whatever sets a request while nobody is logged in, the next tick writes 0 Pa and says so."""
    srv = stepped
    srv.requested[:] = 25e3
    srv.applied[:] = 10e3
    srv.tick()
    assert np.all(srv.requested == 0) and np.all(srv.applied == 0) and np.all(srv.driver.value == 0)
    assert "no client" in srv.events[-1][1]


class RacyServer(BoardServer):
    """Holds each command of the client between its arrival and its execution until the test lets it go:
    the SET is in flight (received, not yet applied) when the board loop's watchdog drops the client (which
    it does, with a command being served, only past its hard limit: the server itself is stuck)."""

    def __init__(self, *a, **kw):
        super().__init__(*a, **kw)
        self.arrived, self.go = threading.Event(), threading.Event()
        self.hold = False
        self.outcome = []

    def _command(self, conn, mtype, body, who):
        if self.hold and mtype == P.MessageType.SET:
            self.arrived.set()
            self.go.wait(DEADLINE)
        try:
            answer = super()._command(conn, mtype, body, who)
        except Exception as e:
            self.outcome.append(type(e).__name__)
            raise
        self.outcome.append("applied")
        return answer


def test_watchdog_drop_with_a_set_in_flight_never_leaves_pressure(tmp_path):
    """1,000 watchdog drops, each with a SET of 40 kPa received by the server: in half of them the SET is
    carried out just before the drop, in the other half just after it (the race of the issue). The board is
    never left pressurized without a client: 0 of 1,000. A command in flight is the client speaking, so the
    drop with it in flight is the hard limit's (the server stuck serving it for > 1.05 s of board time)."""
    clock = Clock()
    srv = RacyServer(MockDriver(2), SECRET, port=0, watchdog=0.05, board_rate=100.0, rate=1e7,
                     clock=clock).start(loop=False)
    left_pressurized, late_refused, n = 0, 0, 1000
    try:
        for i in range(n):
            sock, session, (mtype, _) = raw_login(srv)
            assert mtype == P.MessageType.READY
            after = i % 2 == 1
            srv.hold, srv.arrived, srv.go = after, threading.Event(), threading.Event()
            P.send_frame(sock, session.seal(P.MessageType.SET, P.pack_pressures(1, [40e3, 40e3])))
            if after:
                assert srv.arrived.wait(DEADLINE)
                clock.advance(1.1)                       # past the hard limit max(4 x 0.05, 0.05 + 1) s
            else:
                sealed_answer(sock, session)            # applied: the board answered
                srv.tick()
                assert srv.driver.value[0] == 40e3
                reader_idle(srv)
                clock.advance(0.06)                      # past the watchdog
            srv.tick()                                   # drops the client and vents
            srv.go.set()
            wait_until(lambda: srv.client is None and len(srv.outcome) == i + 1)
            late_refused += srv.outcome[-1] == "_NotClient"
            wait_until(lambda: srv.counters["logins"] == i + 1)
            # no further tick: the state and the DAC must already be vented
            if np.any(srv.requested != 0) or np.any(srv.applied != 0) or np.any(srv.driver.value != 0):
                left_pressurized += 1
            sock.close()
            wait_until(lambda: threading.active_count() < 10)
    finally:
        srv.stop()
    assert left_pressurized == 0
    assert late_refused == n // 2, "every SET that arrived after the drop was refused"
    assert srv.counters["late_commands"] == n // 2


def test_pending_connections_do_not_lock_the_operator_out():
    """A loop connects and disconnects without logging in as fast as it can (several at a time) while the
    operator logs in 100 times: the slot is only taken at login, so every operator login succeeds."""
    with BoardServer(MockDriver(1), SECRET, port=0, max_pending=8, auth_timeout=1.0) as srv:
        stop, attempts = threading.Event(), [0]

        def flood():
            held = []
            while not stop.is_set():
                try:
                    held.append(socket.create_connection(srv.address, timeout=1.0))
                    attempts[0] += 1
                except OSError:
                    continue
                if len(held) > 3:                          # a few idle connections at any time
                    held.pop(0).close()
            for c in held:
                c.close()
        attackers = [threading.Thread(target=flood) for _ in range(2)]
        for th in attackers:
            th.start()
        ok, errors = 0, []
        try:
            for _ in range(100):
                try:
                    with Board.connect(url(srv), secret=SECRET, timeout=DEADLINE, keepalive=False) as brd:
                        brd.set_pressure([1e3])
                        ok += 1
                except ProtocolError as e:
                    errors.append(str(e))
        finally:
            stop.set()
            for th in attackers:
                th.join()
        assert ok >= 99, errors[:3]
        assert attempts[0] > 100, "the flood ran alongside the logins"
        assert srv.counters["logins"] == ok


def test_a_driver_failure_vents_and_refuses_commands():
    class Broken(MockDriver):
        fail = False

        def apply(self, setpoints, t):
            if self.fail and t is not None:
                raise OSError("I2C bus error")
            return super().apply(setpoints, t)
    drv = Broken(1)
    with BoardServer(drv, SECRET, port=0) as srv, Board.connect(url(srv), secret=SECRET) as brd:
        brd.set_pressure([20e3])
        drv.fail = True
        wait_until(lambda: srv.fault is not None)
        assert np.all(srv.applied == 0)
        with pytest.raises(ProtocolError, match="I2C bus error"):
            brd.set_pressure([20e3])


def test_a_failing_plant_step_vents_every_channel_and_refuses_commands_until_the_next_login(monkeypatch):
    """The simulated plant's model step fails (a ConvergenceError out of its Model stepper's advance): apply
    raises, the board vents every channel, refuses commands with the reason, the plant keeps its last converged
    state and does not simulate that tick's time again; the next login commands again."""
    from sorofem.errors import ConvergenceError
    plant = SimulatedPlant(2)
    ok = plant.stepper.advance
    state = {"fail": False, "plant_time": None}

    def step(*a, **k):
        if state["fail"]:
            state["plant_time"] = plant.plant_time
            raise ConvergenceError("Newton did not converge at t = 1 s (injected)")
        return ok(*a, **k)
    monkeypatch.setattr(plant.stepper, "advance", step)
    with BoardServer(plant, SECRET, port=0) as srv:
        with Board.connect(url(srv), secret=SECRET) as brd:
            brd.set_pressure([20e3, -20e3])
            wait_until(lambda: abs(brd.read().measured[0]) > 5e3)
            state["fail"] = True
            wait_until(lambda: srv.fault is not None)
            t_fault = plant.t
            wait_until(lambda: plant.t > t_fault + 0.05)            # the board goes on ticking the plant
            assert "ConvergenceError" in srv.fault and np.all(srv.applied == 0)
            np.testing.assert_array_equal(plant.pressures(), 0.0)    # vented
            assert plant.plant_time == state["plant_time"]          # no step since: its last converged state
            with pytest.raises(ProtocolError, match="Newton did not converge"):
                brd.set_pressure([20e3, -20e3])
        state["fail"] = False
        with Board.connect(url(srv), secret=SECRET) as brd:        # a new login clears the fault
            brd.set_pressure([10e3, 0.0])
            wait_until(lambda: brd.read().measured[0] > 5e3)


def test_a_measured_pressure_outside_the_limits_vents_and_says_why(stepped):
    """The read-back is checked at every tick: a regulator that delivers 40 kPa more than asked at 80 kPa
    leaves the limits (80 kPa + tolerance 31 kPa); after 20 ms (2 ticks at 100 Hz) the board vents, names the
    channel and refuses commands until the next login."""
    srv = stepped

    class Offset(MockDriver):
        def apply(self, setpoints, t):
            measured, sensors, faults = super().apply(setpoints, t)
            return measured + 40e3 * (np.asarray(setpoints) >= 80e3), sensors, faults
    srv.driver = Offset(3)
    assert srv.tolerance[0] == pytest.approx(0.2 * 130e3 + 5e3)
    with Board.connect(url(srv), secret=SECRET, keepalive=False) as brd:
        brd.set_pressure([80e3, 0, 0])
        for _ in range(39):                    # 2 kPa per tick up to 78 kPa
            srv.clock.advance(0.01)
            srv.tick()
            brd.read()
        srv.clock.advance(0.01)
        srv.tick()                             # 80 kPa applied, 120 kPa measured: the first tick outside
        assert srv.fault is None and brd.read().measured[0] == 120e3
        srv.clock.advance(0.01)
        srv.tick()
        assert "channel 0 measures 120.0 kPa" in srv.fault and np.all(srv.driver.value == 0)
        assert any("read-back outside the limits" in e for _, e in srv.events)
        with pytest.raises(ProtocolError, match="channel 0 measures 120.0 kPa"):
            brd.read()


def test_loop_is_paced_and_heartbeats_keep_a_quiet_controller_alive(server):
    with Board.connect(url(server), secret=SECRET, keepalive=False) as brd:     # strict: only the loop feeds it
        brd.set_pressure([10e3, 0, 0])
        ts = list(brd.loop(duration=0.8, rate=50))     # the body sends nothing for 0.8 s > watchdog 0.3 s
        st_ = brd.loop_stats
        assert st_.iterations + st_.missed == 40 and ts[0] == pytest.approx(0.0, abs=1e-12)
        assert np.allclose(np.diff(ts), 0.02 * np.round(np.diff(ts) / 0.02)), "releases on the 50 Hz grid"
        assert brd.read().requested[0] == 10e3, "heartbeats must have kept the board from venting"
    with pytest.raises(ParameterError):
        next(brd.loop(0, 10))


def test_interactive_keepalive_survives_a_pause_and_strict_mode_does_not(server):
    """A person at a prompt: connect, pause 2 s (> 6 watchdog times), set a pressure and read it back. In
    strict mode the same pause loses the session (the board vented)."""
    with Board.connect(url(server), secret=SECRET) as brd:
        time.sleep(2.0)
        brd.set_pressure([15e3, 0, 0])
        wait_until(lambda: brd.read().measured[0] == 15e3)
        assert not any("watchdog" in e for _, e in server.events)
    with Board.connect(url(server), secret=SECRET, keepalive=False) as brd:
        time.sleep(2.0)
        with pytest.raises(ProtocolError):
            brd.set_pressure([15e3, 0, 0])
    assert any("watchdog" in e for _, e in server.events)


def test_bad_arguments(tmp_path):
    with pytest.raises(ParameterError, match="tcp://"):
        Board.connect("http://localhost:80", secret=SECRET)
    with pytest.raises(ParameterError, match="empty"):
        Board.connect("tcp://127.0.0.1:1", secret="")
    with pytest.raises(ParameterError, match="too weak.*urandom"):
        Board.connect("tcp://127.0.0.1:1", secret="x")
    with pytest.raises(ParameterError, match="does not exist"):
        Board.connect("tcp://127.0.0.1:1", secret_file=tmp_path / "nope")
    with pytest.raises(ProtocolError, match="cannot reach"):
        Board.connect("tcp://127.0.0.1:1", secret=SECRET)
    with pytest.raises(ParameterError, match="0 Pa"):
        BoardServer(MockDriver(1), SECRET, port=0, p_min=10e3)
    with pytest.raises(ParameterError, match="too weak"):
        BoardServer(MockDriver(1), "s3cret", port=0)
    with pytest.raises(ParameterError, match="channels"):
        MockDriver(0)


def test_the_client_and_the_board_read_a_secret_file_alike(tmp_path):
    """One whitespace rule on both sides: a secret file with a trailing newline (what `echo` and editors
    write) logs in whether the client gets the file or the text."""
    f = tmp_path / "secret"
    f.write_text(SECRET + "\n")
    with BoardServer(MockDriver(1), P.read_secret_file(f), port=0) as srv:
        for kw in (dict(secret_file=f), dict(secret=f.read_text()), dict(secret=" " + SECRET)):
            with Board.connect(url(srv), keepalive=False, **kw) as brd:
                brd.read()


@pytest.mark.parametrize("content,match", [(None, "does not exist"), ("", "empty"), ("abc\n", "too weak")])
def test_the_server_command_says_what_is_wrong_with_its_secret_file(tmp_path, content, match):
    f = tmp_path / "secret"
    if content is not None:
        f.write_text(content)
    r = subprocess.run([sys.executable, "-m", "sorocontrol.server", "--driver", "mock", "--port", "0",
                        "--secret-file", str(f)], capture_output=True, text=True, timeout=60)
    assert r.returncode != 0 and match in r.stderr and "Traceback" not in r.stderr and "urandom" in r.stderr


def test_plant_is_an_import_path_never_a_pickle_file(tmp_path):
    """``--plant`` takes MODULE:NAME; a pickle file is refused (it would run code); the private pipe of
    Board.simulated refuses a file on stdin."""
    import pickle
    bomb = tmp_path / "plant.pkl"
    bomb.write_bytes(pickle.dumps({"volume": 1e-5}))
    r = subprocess.run([sys.executable, "-m", "sorocontrol.server", "--port", "0", "--secret", SECRET,
                        "--plant", str(bomb)], capture_output=True, text=True, timeout=60)
    assert r.returncode != 0 and "MODULE:NAME" in r.stderr
    with open(bomb, "rb") as f:
        r = subprocess.run([sys.executable, "-m", "sorocontrol.server", "--port", "0", "--secret", SECRET,
                            "--plant-from-parent"], stdin=f, capture_output=True, text=True, timeout=60)
    assert r.returncode != 0 and "never from a file" in r.stderr
    mod = tmp_path / "my_plant.py"
    mod.write_text("PLANT = dict(volume=1e-5, time_constant=0.02)\n")
    env = dict(os.environ, PYTHONPATH=f"{tmp_path}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    proc = subprocess.Popen([sys.executable, "-m", "sorocontrol.server", "--port", "0", "--secret", SECRET,
                             "--channels", "1", "--plant", "my_plant:PLANT"], stdout=subprocess.PIPE, text=True, env=env)
    try:
        port = int(proc.stdout.readline().split()[2])
        with Board.connect(f"tcp://127.0.0.1:{port}", secret=SECRET) as brd:
            brd.set_pressure([10e3])
            wait_until(lambda: abs(brd.read().measured[0] - 10e3) < 100)
    finally:
        proc.terminate()
        proc.wait(DEADLINE)
        proc.stdout.close()
    assert proc.returncode == 0


HOLDER = textwrap.dedent("""
    import time
    from sorocontrol import Board
    brd = Board.simulated(channels=1)
    brd.set_pressure([30e3])
    print(brd.server_process.pid, flush=True)
    time.sleep(600)
""")


def _gone(pid):
    """True when process ``pid`` has exited (reaped, or a zombie waiting for its new parent)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] in ("Z", "X")
    except FileNotFoundError:
        return True


def test_a_simulated_board_never_outlives_its_parent():
    """SIGKILL the process that holds a Board.simulated(): its server process sees the pipe from its parent
    close, vents and exits (about at once; the test polls with a generous deadline)."""
    holder = subprocess.Popen([sys.executable, "-c", HOLDER], stdout=subprocess.PIPE, text=True)
    try:
        server_pid = int(holder.stdout.readline())
        assert not _gone(server_pid)
        os.kill(holder.pid, signal.SIGKILL)
        holder.wait()
        wait_until(lambda: _gone(server_pid))
    finally:
        holder.kill()
        holder.wait()
        holder.stdout.close()
        if not _gone(server_pid):
            os.kill(server_pid, signal.SIGKILL)


def test_simulated_plant_follows_the_closed_form_step_response():
    """Unsaturated regulator loop: p/p_ref = 1 - exp(-a t)(1 - a t), a = 1/(2 tau) (drivers docstring)."""
    tau, pref = 0.03, 20e3
    plant = SimulatedPlant(2, time_constant=tau, substep=1e-4)
    t = np.linspace(0, 0.25, 51)[1:]
    p = np.array([plant.apply([pref, -pref], ti)[0] for ti in t])
    a = 1 / (2 * tau)
    exact = pref * (1 - np.exp(-a * t) * (1 - a * t))
    np.testing.assert_allclose(p[:, 0], exact, atol=1e-4 * pref)
    np.testing.assert_allclose(p[:, 1], -exact, atol=1e-4 * pref)
    assert p[:, 0].max() == pytest.approx(pref * (1 + np.exp(-2)), rel=2e-3)   # the 13.5 % overshoot at 4 tau


def test_simulated_board_reaches_the_setpoint():
    with Board.simulated(channels=2, time_constant=0.02) as brd:
        time.sleep(1.0)        # set-up work longer than the watchdog: the keepalive holds the session
        brd.set_pressure([30e3, -30e3])
        wait_until(lambda: brd.read().time > brd.state.time * 0 + 0.4 and np.allclose(
            brd.state.measured, [30e3, -30e3], rtol=0.01))
        proc = brd.server_process
    assert proc.poll() == 0, "closing a simulated board stops its process (it vents and exits by itself)"


def test_a_lost_simulated_board_says_why():
    """A simulated board whose server dies: the client's error names the connection's end and the server's
    state and log, not only "Broken pipe"; later commands repeat the reason."""
    with Board.simulated(channels=1, keepalive=False) as brd:
        brd.set_pressure([10e3])
        os.kill(brd.server_process.pid, signal.SIGKILL)
        with pytest.raises(ProtocolError, match=r"simulated board's server \(exited with status -9\) logged"):
            wait_until(lambda: brd.read() is None)        # until the loss shows (the first send may succeed)
        with pytest.raises(ProtocolError, match=r"the board connection was lost: .*exited with status -9"):
            brd.read()


def test_a_late_simulated_plant_skips_time_instead_of_stalling(caplog):
    """Board time that passed beyond max_advance since the plant's last step (a busy host) is skipped, not
    simulated: the call costs at most max_advance of plant time, so it never grows with the delay. The
    pressures are those of a plant that ran max_advance, the skipped time is counted and logged."""
    late, ref = SimulatedPlant(2, max_advance=0.025), SimulatedPlant(2, max_advance=0.025)
    for plant in (late, ref):
        plant.apply([20e3, -20e3], 0.01)
    with caplog.at_level("WARNING", logger="sorocontrol.drivers"):
        p_late = late.apply([20e3, -20e3], 2.01)[0]     # 2 s after the last step
    p_ref = ref.apply([20e3, -20e3], 0.035)[0]
    np.testing.assert_allclose(p_late, p_ref, rtol=1e-12)    # the same 25 ms of the plant's model
    assert late.t == 2.01 and late.late == 1 and late.skipped == pytest.approx(1.975, abs=1e-12)
    assert "skipped the rest" in caplog.text and "2000 ms of board time passed" in caplog.text
    p_next = late.apply([20e3, -20e3], 2.02)[0]          # and goes on from there at the board's pace
    np.testing.assert_allclose(p_next, ref.apply([20e3, -20e3], 0.045)[0], rtol=1e-12)
    assert late.late == 1
    with pytest.raises(ParameterError, match="max_advance"):
        SimulatedPlant(1, max_advance=0.0)
