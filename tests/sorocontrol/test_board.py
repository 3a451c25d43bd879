"""Board server and client: login, limits, watchdog, one client at a time, robustness to bad peers, the
simulated plant against its closed-form step response, and the real-time loop."""
import os
import signal
import socket
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sorocontrol import Board, BoardServer, MockDriver, SimulatedPlant
from sorocontrol import protocol as P
from sorofem.errors import ParameterError, ProtocolError

SECRET = "correct horse battery staple"


@pytest.fixture
def server():
    srv = BoardServer(MockDriver(3), SECRET, port=0, watchdog=0.3, rate=200e3, p_min=-50e3, p_max=80e3).start()
    yield srv
    srv.stop()


def url(srv):
    return f"tcp://127.0.0.1:{srv.address[1]}"


def wait_until(cond, timeout=2.0):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if cond():
            return time.monotonic() - t0
        time.sleep(0.002)
    raise AssertionError("condition not reached")


def raw_login(srv, secret=SECRET):
    sock = socket.create_connection(srv.address, timeout=2.0)
    mtype, payload = P.read_frame(sock)
    hello = P.unpack_hello(payload)
    nc = P.new_nonce()
    sock.sendall(P.encode(P.MessageType.AUTH, P.pack_auth(nc, P.client_proof(secret, hello.nonce, nc))))
    return sock, P.read_frame(sock)


def test_login_announces_limits_and_commands_answer_with_state(server):
    with Board.connect(url(server), secret=SECRET) as brd:
        assert brd.channels == 3 and brd.watchdog == 0.3
        np.testing.assert_array_equal(brd.p_max, 80e3)
        s = brd.set_pressure([10e3, -5e3, 0.0])
        np.testing.assert_array_equal(s.requested, [10e3, -5e3, 0.0])
        assert s.sequence == 1 and brd.read().sequence == 2
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


def test_rate_limit_slews_the_applied_pressure(server):
    with Board.connect(url(server), secret=SECRET) as brd:
        brd.set_pressure([80e3, 0, 0])
        t0 = time.monotonic()
        samples = []
        while time.monotonic() - t0 < 0.5:
            s = brd.read()
            samples.append((s.time, s.applied[0], bool(s.flags[0] & P.Flag.RATE_LIMITED)))
            time.sleep(0.01)
        t, p, limited = map(np.array, zip(*samples))
        rising = (p > 5e3) & (p < 75e3)
        slope = np.polyfit(t[rising], p[rising], 1)[0]
        assert slope == pytest.approx(200e3, rel=0.1)            # the rate limit [Pa/s]
        assert np.all(np.diff(p) <= 200e3 * np.diff(t) * 1.1 + 1e3)
        assert limited[rising].all() and not limited[-1] and p[-1] == 80e3


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
    sock.sendall(bytes(frame))
    mtype, payload = P.read_frame(sock)
    assert mtype == P.MessageType.ERROR and P.unpack_error(payload)[0] == P.ErrorCode.VERSION
    sock.close()


def test_bad_secret_is_refused_and_the_server_goes_on(server):
    with pytest.raises(ProtocolError, match="AUTH"):
        Board.connect(url(server), secret="wrong")
    assert any("authentication failed" in e for _, e in server.events)
    with Board.connect(url(server), secret=SECRET) as brd:
        assert brd.read() is not None


def test_client_checks_the_board_knows_the_secret():
    """A fake board that answers READY without knowing the secret is detected (mutual authentication)."""
    lst = socket.create_server(("127.0.0.1", 0))

    def fake():
        conn, _ = lst.accept()
        conn.sendall(P.encode(P.MessageType.HELLO, P.pack_hello(
            P.Hello(1, 1, 0.5, 400.0, [-1.0], [1.0], [1.0], P.new_nonce()))))
        P.read_frame(conn)
        conn.sendall(P.encode(P.MessageType.READY, b"\x00" * 32))
        time.sleep(0.2)
        conn.close()
    import threading
    th = threading.Thread(target=fake)
    th.start()
    with pytest.raises(ProtocolError, match="could not prove"):
        Board.connect(f"tcp://127.0.0.1:{lst.getsockname()[1]}", secret=SECRET)
    th.join()
    lst.close()


@pytest.mark.parametrize("garbage", [
    b"hello world\n",
    P.encode(P.MessageType.SET, b"\x00" * 3),                       # wrong payload size
    P.encode(P.MessageType.HELLO, b""),                             # a server message from a client
    P.encode(P.MessageType.SET, P.pack_pressures(1, [np.nan, 0, 0])),  # non-finite set-point
    P.encode(P.MessageType.READ, P.pack_sequence(1))[:-1] + b"\xff",  # bad checksum
])
def test_malformed_frames_after_login_vent_and_the_server_survives(server, garbage):
    sock, (mtype, _) = raw_login(server)
    assert mtype == P.MessageType.READY
    sock.sendall(P.encode(P.MessageType.SET, P.pack_pressures(1, [30e3, 0, 0])))
    P.read_frame(sock)
    sock.sendall(garbage)
    mtype, payload = P.read_frame(sock)
    assert mtype == P.MessageType.ERROR, "the server answers a bad frame with ERROR"
    code, _ = P.unpack_error(payload)
    assert code == (P.ErrorCode.UNEXPECTED if garbage[3:4] == bytes([P.MessageType.HELLO]) else P.ErrorCode.MALFORMED)
    wait_until(lambda: server._client is None and np.all(server.requested == 0))
    sock.close()
    with Board.connect(url(server), secret=SECRET) as brd:   # still serving
        assert brd.read().sequence == 1


@settings(max_examples=25, deadline=None)
@given(st.binary(min_size=1, max_size=300))
def test_fuzz_the_live_server_with_random_bytes(data):
    with BoardServer(MockDriver(2), SECRET, port=0, watchdog=0.3) as srv:
        for logged_in in (False, True):
            if logged_in:
                sock, _ = raw_login(srv)
            else:
                sock = socket.create_connection(srv.address, timeout=2.0)
                P.read_frame(sock)   # HELLO
            sock.sendall(data)
            sock.settimeout(1.0)
            try:
                while sock.recv(4096):
                    pass
            except (socket.timeout, ConnectionError):
                pass
            sock.close()
            wait_until(lambda: srv._client is None, timeout=3.0)
        with Board.connect(url(srv), secret=SECRET) as brd:
            assert brd.read() is not None


CLIENT = textwrap.dedent("""
    import sys, time
    from sorocontrol import Board
    brd = Board.connect(sys.argv[1], secret=sys.argv[2])
    brd.set_pressure([40e3, 0, 0])
    print("ready", flush=True)
    while True:
        time.sleep(0.05)
        brd.heartbeat()
""")


@pytest.mark.parametrize("how", ["kill", "stop"])
def test_watchdog_vents_when_the_client_dies_or_hangs(server, how):
    """SIGKILL: the kernel closes the socket, the server vents at once. SIGSTOP: the socket stays open and
    silent; the watchdog (0.3 s) must vent within its timeout plus one board tick."""
    proc = subprocess.Popen([sys.executable, "-c", CLIENT, url(server), SECRET], stdout=subprocess.PIPE,
                            text=True, cwd=os.getcwd())
    try:
        assert proc.stdout.readline().strip() == "ready"
        wait_until(lambda: server.driver.value[0] > 39e3)
        t0 = time.monotonic()
        os.kill(proc.pid, signal.SIGKILL if how == "kill" else signal.SIGSTOP)
        elapsed = wait_until(lambda: server.driver.value[0] == 0.0, timeout=3.0)
        vented = time.monotonic() - t0
        assert vented <= server.watchdog + 2.0 / server.board_rate + 0.05, vented
        if how == "stop":
            assert any("watchdog" in e for _, e in server.events) and vented >= server.watchdog - 0.06
        assert elapsed is not None
    finally:
        proc.kill()
        proc.wait()
        proc.stdout.close()


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
        wait_until(lambda: srv._fault is not None)
        assert np.all(srv.applied == 0)
        with pytest.raises(ProtocolError, match="I2C bus error"):
            brd.set_pressure([20e3])


def test_loop_is_paced_and_heartbeats_keep_a_quiet_controller_alive(server):
    with Board.connect(url(server), secret=SECRET) as brd:
        brd.set_pressure([10e3, 0, 0])
        ts = list(brd.loop(duration=0.8, rate=50))     # the body sends nothing for 0.8 s > watchdog 0.3 s
        st_ = brd.loop_stats
        assert st_.iterations == 40 and ts[1] == pytest.approx(0.02)
        assert st_.rate == pytest.approx(50, rel=0.02) and st_.missed == 0
        assert brd.read().requested[0] == 10e3, "heartbeats must have kept the board from venting"
    with pytest.raises(ParameterError):
        next(brd.loop(0, 10))


def test_bad_arguments():
    with pytest.raises(ParameterError, match="tcp://"):
        Board.connect("http://localhost:80", secret="x")
    with pytest.raises(ParameterError, match="secret"):
        Board.connect("tcp://127.0.0.1:1", secret="")
    with pytest.raises(ProtocolError, match="cannot reach"):
        Board.connect("tcp://127.0.0.1:1", secret="x")
    with pytest.raises(ParameterError, match="0 Pa"):
        BoardServer(MockDriver(1), SECRET, port=0, p_min=10e3)
    with pytest.raises(ParameterError, match="channels"):
        MockDriver(0)


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
        brd.set_pressure([30e3, -30e3])
        time.sleep(0.4)
        s = brd.read()
        np.testing.assert_allclose(s.measured, [30e3, -30e3], rtol=0.01)
        proc = brd._process
    assert proc.poll() is not None, "closing a simulated board stops its process"


def test_simulated_plant_is_the_fluidic_model():
    plant = SimulatedPlant(3, max_flow=1e-5)   # saturating for large errors
    rng = np.random.default_rng(1)
    x = plant.x + rng.normal(size=plant.x.shape) * [1e-7, 10.0]
    u = np.array([50e3, -80e3, 1e3])
    exact = np.array([plant.fluidic.rhs(x[i], u[i:i + 1], plant.volume) for i in range(3)])
    np.testing.assert_allclose(plant._rhs(x, u), exact, rtol=1e-12, atol=1e-20)
