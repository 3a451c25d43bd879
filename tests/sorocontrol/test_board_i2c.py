"""The real board's I²C path against a stub bus (``tests/sorocontrol/stub_i2c/smbus2.py``) that records every
DAC code and answers the ADCs from a model of the regulators.

Over several calibrations (the regulator's signal range, in a board profile) and safety limits: at idle, on
VENT, on the watchdog, after SIGTERM and after the unit's ExecStopPost vent command (following a SIGKILL of
the server) every DAC holds the code of 0 kPa gauge of its calibration; a request at a limit writes the
limit's code and a request beyond it never more. A wrong calibration (vent writes a code that is not 0 kPa on
the real regulator) is caught by the read-back check. Waits on real time use generous deadlines.
"""
import importlib.util
import json
import os
import shlex
import signal
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from sorocontrol import Board, BoardServer
from sorocontrol import protocol as P
from sorocontrol.drivers import BoardProfile, ChannelCalibration, I2CDriver
from sorofem.errors import ParameterError

ROOT = Path(__file__).resolve().parents[2]
STUB_DIR = Path(__file__).resolve().parent / "stub_i2c"
UNIT = ROOT / "hardware" / "soro-board.service"
SECRET = "4f0c2a9d51e6b7384c2d9a0f6e1b5c73"
DEADLINE = 20.0
DACS = (0x60, 0x61)

# (signal range of the regulators = the profile's calibration [Pa], safety limits [Pa])
SETTINGS = {
    "veab_limits_50": ((-100e3, 100e3), (-50e3, 50e3)),        # issue 16, case 1: 50 kPa wrote full scale
    "veab_positive_limits": ((-100e3, 100e3), (0.0, 60e3)),     # case 2: vent wrote code 0 = -100 kPa
    "pressure_only_regulator": ((0.0, 200e3), (0.0, 150e3)),    # a 0..200 kPa regulator: 0 kPa is code 0
    "asymmetric": ((-50e3, 150e3), (-20e3, 100e3)),
}


def write_profile(path, signal_range, limits=None):
    """A two-channel profile; ``limits``: per channel ``(p_min, p_max)`` [Pa] written as its keys, or None."""
    chans = "".join(textwrap.dedent(f"""
        [[channels]]
        dac = {dac:#x}
        adc = [0x48, {i}]
        signal_range = [{signal_range[0]!r}, {signal_range[1]!r}]
        sensor_gain = 20e3
        sensor_offset = 5.0
        divider = 3.0
        """) + (f"p_min = {limits[i][0]!r}\np_max = {limits[i][1]!r}\n" if limits else "")
        for i, dac in enumerate(DACS))
    path.write_text(f'format = "soro-board-profile"\nversion = 1\ni2c_bus = 1\n{chans}')
    return path


def regulators(signal_range):
    """The stub's true regulators: as calibrated (``signal_range``) unless a test says otherwise."""
    return {dac: [0x48, i, signal_range[0], signal_range[1], 20e3, 5.0, 3.0] for i, dac in enumerate(DACS)}


@pytest.fixture
def stub(monkeypatch):
    spec = importlib.util.spec_from_file_location("smbus2", STUB_DIR / "smbus2.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    monkeypatch.setitem(sys.modules, "smbus2", mod)
    return mod


class Clock:
    def __init__(self):
        self.t = 50.0

    def __call__(self):
        return self.t


def url(srv):
    return f"tcp://127.0.0.1:{srv.address[1]}"


def codes(stub):
    return [stub.CODES.get(dac) for dac in DACS]


@pytest.mark.parametrize("setting", sorted(SETTINGS))
def test_dac_codes_at_idle_vent_watchdog_and_at_the_limits(stub, tmp_path, setting):
    signal_range, (p_min, p_max) = SETTINGS[setting]
    stub.reset(regulators(signal_range))
    profile = BoardProfile.load(write_profile(tmp_path / "profile.toml", signal_range))
    cal = profile.channels[0]
    zero, lsb = cal.vent_code, (signal_range[1] - signal_range[0]) / 4095
    assert abs(cal.pressure(zero)) <= lsb / 2, "the vent code is 0 kPa within half a code"
    clock = Clock()
    srv = BoardServer(I2CDriver(profile), SECRET, port=0, p_min=p_min, p_max=p_max, rate=1e9, watchdog=0.3,
                      board_rate=100.0, clock=clock).start(loop=False)

    def tick(n=1):
        for _ in range(n):
            clock.t += 0.01
            srv.tick()
    try:
        tick(3)
        assert codes(stub) == [zero, zero], "idle"
        with Board.connect(url(srv), secret=SECRET, keepalive=False) as brd:
            for request, limit in ((p_max, p_max), (2 * p_max + 10e3, p_max), (p_min, p_min),
                                   (2 * p_min - 10e3, p_min)):
                brd.set_pressure([request, 0.0])
                tick()
                limit_code = cal.code(limit)
                assert codes(stub) == [limit_code, zero], (request, limit)
                if limit > 0:   # never more pressure than the limit, less by under one code
                    assert limit - lsb < cal.pressure(limit_code) <= limit
                elif limit < 0:
                    assert limit <= cal.pressure(limit_code) < limit + lsb
                else:
                    assert limit_code == zero
                assert brd.read().measured[0] == pytest.approx(cal.pressure(limit_code), abs=lsb * 10)
            brd.set_pressure([p_max, p_min])
            tick()
            brd.vent()
            assert codes(stub) == [zero, zero], "VENT"
            brd.set_pressure([p_max, p_max])
            tick()
            assert codes(stub)[0] == cal.code(p_max)
            deadline = time.monotonic() + 10.0       # the server has served the last command (generous: load)
            while srv.serving and time.monotonic() < deadline:
                time.sleep(0.001)
            clock.t += 0.31                          # the client goes silent past the watchdog
            srv.tick()
            assert codes(stub) == [zero, zero], "watchdog"
            assert srv.client is None and srv.fault is None
        tick(2)
        assert codes(stub) == [zero, zero]
    finally:
        srv.stop()
    assert codes(stub) == [zero, zero], "stop"
    assert max(c for _, c in stub.WRITES) <= max(cal.code(p_max), zero), "no code beyond the upper limit's, ever"
    assert min(c for _, c in stub.WRITES) >= min(cal.code(p_min), zero), "nor below the lower limit's"


def test_a_wrong_calibration_is_caught_by_the_read_back(stub, tmp_path):
    """The profile says 0..60 kPa, the regulators really span -100..100 kPa: the board's vent code 0 gives
    -100 kPa. The read-back check sees the channels outside the limits and says which and why."""
    stub.reset(regulators((-100e3, 100e3)))
    profile = BoardProfile.load(write_profile(tmp_path / "profile.toml", (0.0, 60e3)))
    clock = Clock()
    srv = BoardServer(I2CDriver(profile), SECRET, port=0, p_min=0.0, p_max=60e3, board_rate=100.0, clock=clock)
    try:
        for _ in range(3):
            clock.t += 0.01
            srv.tick()
        assert "channel 0 measures -100.0 kPa" in srv.fault and "calibration in the board profile" in srv.fault
        assert any("read-back outside the limits" in e for _, e in srv.events)
    finally:
        srv.stop()


def test_limits_outside_the_calibration_and_bad_profiles_are_refused(stub, tmp_path):
    profile = BoardProfile.load(write_profile(tmp_path / "profile.toml", (0.0, 200e3)))
    with pytest.raises(ParameterError, match="calibrated range"):
        BoardServer(I2CDriver(profile), SECRET, port=0, p_min=-50e3, p_max=50e3)
    with pytest.raises(ParameterError, match="does not exist"):
        BoardProfile.load(tmp_path / "nope.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text('format = "soro-board-profile"\nversion = 1\n[[channels]]\ndac = 0x60\nadc = [0x48, 0]\n'
                   'signal_range = [-100e3, 100e3]\np_range = [0, 1]\n')
    with pytest.raises(ParameterError, match="unknown keys \\['p_range'\\]"):
        BoardProfile.load(bad)
    with pytest.raises(ParameterError, match="contain 0 Pa"):
        ChannelCalibration(0x60, (0x48, 0), (10e3, 100e3))
    assert BoardProfile.load(ROOT / "hardware" / "profiles" / "veab-2ch.toml").channels[1].dac == 0x61


# ---- per-channel safety limits in the profile ---------------------------------------------------------------

# the manipulator's (d) bellows and gripper: -10..30 kPa and -30..60 kPa on VEAB regulators
PER_CHANNEL = ((-10e3, 30e3), (-30e3, 60e3))


@pytest.mark.parametrize("given", [None, (-100e3, 100e3), (-20e3, 45e3)],
                         ids=["profile_only", "wider_pair_given", "narrower_pair_given"])
def test_per_channel_limits_of_the_profile_are_enforced(stub, tmp_path, given):
    """A set-point above one channel's limit but below the other's is clamped on that channel only (flag
    CLAMPED), and its DAC never receives a code beyond that channel's limit; a --p-min/--p-max pair given to
    the server only narrows the profile's limits, never widens them."""
    signal_range = (-100e3, 100e3)
    stub.reset(regulators(signal_range))
    profile = BoardProfile.load(write_profile(tmp_path / "profile.toml", signal_range, PER_CHANNEL))
    assert profile.limits == PER_CHANNEL
    cal = profile.channels[0]
    zero = cal.vent_code
    kw = {} if given is None else dict(p_min=given[0], p_max=given[1])
    lo = np.array([lim[0] for lim in PER_CHANNEL]) if given is None else np.maximum(given[0], [-10e3, -30e3])
    hi = np.array([lim[1] for lim in PER_CHANNEL]) if given is None else np.minimum(given[1], [30e3, 60e3])
    clock = Clock()
    srv = BoardServer(I2CDriver(profile), SECRET, port=0, rate=1e9, board_rate=100.0, clock=clock,
                      **kw).start(loop=False)
    np.testing.assert_array_equal(srv.p_min, lo)
    np.testing.assert_array_equal(srv.p_max, hi)

    def tick():
        clock.t += 0.01
        srv.tick()
    try:
        with Board.connect(url(srv), secret=SECRET, keepalive=False) as brd:
            np.testing.assert_array_equal(brd.p_max, hi)         # announced at login
            for request in ([40e3, 40e3], [55e3, 55e3], [90e3, 90e3], [-25e3, -25e3], [-60e3, -60e3],
                            [20e3, -5e3]):
                state = brd.set_pressure(request)
                tick()
                expected = np.clip(request, lo, hi)
                np.testing.assert_array_equal(brd.read().requested, expected)
                assert state.flagged(P.Flag.CLAMPED).tolist() == np.flatnonzero(expected != request).tolist()
                assert codes(stub) == [cal.code(e) for e in expected], request
            brd.vent()
            assert codes(stub) == [zero, zero]
    finally:
        srv.stop()
    for c, dac in enumerate(DACS):       # never a code beyond the channel's own limits, at any write
        written = [code for addr, code in stub.WRITES if addr == dac]
        assert max(written) == cal.code(hi[c]) and min(written) == cal.code(lo[c])
        assert lo[c] <= cal.pressure(min(written)) and cal.pressure(max(written)) <= hi[c]
    assert cal.code(hi[0]) < cal.code(hi[1]), "the test must tell the channels apart"


def test_the_units_server_takes_the_limits_from_the_profile(tmp_path):
    """The server as the unit starts it (--driver i2c --profile, board.env's pair dropped, then a wider pair
    given): each DAC is capped at its channel's limit from the profile."""
    signal_range = (-100e3, 100e3)
    profile = write_profile(tmp_path / "profile.toml", signal_range, PER_CHANNEL)
    cal = BoardProfile.load(profile).channels[0]
    for extra in ([], ["--p-min", "-100000", "--p-max", "100000"]):
        log = tmp_path / "i2c.log"
        log.write_text("")
        argv = unit_command("ExecStart", profile)
        argv = [a for a in argv if a not in ("${SORO_BOARD_HOST}", "$SORO_BOARD_ARGS")]
        argv = [a for a, prev in zip(argv, [None] + argv) if prev != "--secret-file" and a != "--secret-file"]
        argv[argv.index("--host") + 1:argv.index("--host") + 1] = ["127.0.0.1"]
        argv[argv.index("--port") + 1] = "0"
        proc = subprocess.Popen(argv + ["--board-rate", "100"] + extra, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True, env=stub_env(log, signal_range))
        try:
            line = proc.stdout.readline()
            assert line.startswith("listening"), proc.stderr.read() if proc.poll() is not None else line
            with Board.connect(f"tcp://127.0.0.1:{line.split()[2]}", secret=SECRET) as brd:
                np.testing.assert_array_equal(brd.p_max, [30e3, 60e3])
                brd.set_pressure([50e3, 50e3])
                wait_until(lambda: logged_codes(log) == [cal.code(30e3), cal.code(50e3)])
        finally:
            proc.terminate()
            proc.wait(DEADLINE)
            proc.stdout.close()
            proc.stderr.close()
        assert logged_codes(log) == [cal.vent_code] * 2
        assert max(int(ln.split()[1]) for ln in log.read_text().splitlines() if ln.split()[0] == str(DACS[0])) \
            == cal.code(30e3)


CHANNEL = """
[[channels]]
dac = 0x60
adc = [0x48, 0]
signal_range = [-100e3, 100e3]
"""


@pytest.mark.parametrize("text, message", [
    (CHANNEL + "p_max = 30e3\n", "channel 0 \\(channel 0\\): p_max given without p_min"),
    (CHANNEL + "p_min = -10e3\n", "p_min given without p_max"),
    (CHANNEL + "p_min = 5e3\np_max = 30e3\n", "p_min = 5000 Pa must be <= 0 Pa"),
    (CHANNEL + "p_min = -10e3\np_max = -5e3\n", "p_max = -5000 Pa must be >= 0 Pa"),
    (CHANNEL + "p_min = -10e3\np_max = 150e3\n", "p_max = 150000 Pa is above the calibrated signal_range"),
    (CHANNEL + "p_min = -150e3\np_max = 10e3\n", "p_min = -150000 Pa is below the calibrated signal_range"),
    (CHANNEL + 'p_min = -10e3\np_max = "30 kPa"\n', "p_max = '30 kPa' must be a number"),
    (CHANNEL + "p_min = -10e3\np_max = nan\n", "p_max = nan must be a finite"),
    (CHANNEL + "p_min = -10e3\np_max = 30e3\n" + CHANNEL.replace("0x60", "0x61"),
     "channels \\[0\\] have safety limits \\(p_min/p_max\\) and channels \\[1\\] do not"),
    ('[safety_limits]\n"channel 0" = [-10e3, 30e3]\n' + CHANNEL,
     "unknown top-level keys \\['safety_limits'\\] \\(safety limits go into each \\[\\[channels\\]\\] table as p_min/p_max"),
    ("p_max = 30e3\n" + CHANNEL, "unknown top-level keys \\['p_max'\\]"),
], ids=["p_max_alone", "p_min_alone", "p_min_positive", "p_max_negative", "p_max_beyond_calibration",
        "p_min_beyond_calibration", "not_a_number", "nan", "some_channels_only", "safety_limits_table",
        "top_level_pair"])
def test_inconsistent_or_misplaced_limits_are_refused_naming_the_key(tmp_path, text, message):
    path = tmp_path / "profile.toml"
    path.write_text('format = "soro-board-profile"\nversion = 1\n' + text)
    with pytest.raises(ParameterError, match=message):
        BoardProfile.load(path)


def test_profile_limits_checked_when_built_in_python_and_profile_refused_by_simulated_boards():
    cal = ChannelCalibration(0x60, (0x48, 0), (0.0, 200e3))
    assert BoardProfile((cal,), limits=((0.0, 150e3),)).limits == ((0.0, 150e3),)
    with pytest.raises(ParameterError, match="p_min = -10000 Pa is below"):
        BoardProfile((cal,), limits=((-10e3, 150e3),))
    with pytest.raises(ParameterError, match="every channel or none"):
        BoardProfile((cal, cal), limits=((0.0, 150e3),))
    from sorocontrol.drivers import MockDriver

    class BadLimits(MockDriver):
        safety_limits = property(lambda self: (np.array([5e3]), np.array([50e3])))
    with pytest.raises(ParameterError, match="driver's safety limits"):
        BoardServer(BadLimits(1), SECRET, port=0)
    r = subprocess.run([sys.executable, "-m", "sorocontrol.server", "--driver", "mock", "--profile", "x.toml",
                        "--secret", SECRET, "--port", "0"], capture_output=True, text=True, timeout=60)
    assert r.returncode != 0 and "does not read it" in r.stderr and "Traceback" not in r.stderr


# ---- the server as the unit runs it: SIGTERM, SIGKILL + ExecStopPost ---------------------------------------

def unit_command(key, profile):
    """The unit's ``key=`` command line (continuations joined), for this machine: our Python, our profile."""
    text = UNIT.read_text().replace("\\\n", " ")
    line = next(ln for ln in text.splitlines() if ln.startswith(f"{key}="))
    argv = shlex.split(line.split("=", 1)[1])
    return [sys.executable if a == "/opt/soro/.venv/bin/python" else
            str(profile) if a == "/etc/soro-board/profile.toml" else a for a in argv]


def logged_codes(log):
    """The last code written to each DAC, from the stub's log file."""
    last = {}
    for ln in log.read_text().splitlines():
        addr, code = ln.split()[:2]
        last[int(addr)] = int(code)
    return [last.get(dac) for dac in DACS]


def stub_env(log, signal_range):
    return dict(os.environ, PYTHONPATH=os.pathsep.join([str(STUB_DIR), os.environ.get("PYTHONPATH", "")]),
                STUB_SMBUS_LOG=str(log), STUB_SMBUS_REGULATORS=json.dumps(
                    {str(k): v for k, v in regulators(signal_range).items()}), SORO_BOARD_SECRET=SECRET)


def start_unit_server(tmp_path, setting):
    signal_range, (p_min, p_max) = SETTINGS[setting]
    profile = write_profile(tmp_path / "profile.toml", signal_range)
    log = tmp_path / "i2c.log"
    log.write_text("")
    argv = unit_command("ExecStart", profile)
    argv = [a for a in argv if a not in ("${SORO_BOARD_HOST}", "$SORO_BOARD_ARGS")]
    argv = [a for a, prev in zip(argv, [None] + argv) if prev != "--secret-file" and a != "--secret-file"]
    argv[argv.index("--host") + 1:argv.index("--host") + 1] = ["127.0.0.1"]
    argv[argv.index("--port") + 1] = "0"
    argv += ["--p-min", repr(p_min), "--p-max", repr(p_max), "--board-rate", "100", "--watchdog", "0.5"]
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=stub_env(log, signal_range))
    line = proc.stdout.readline()
    assert line.startswith("listening"), proc.stderr.read() if proc.poll() is not None else line
    return proc, f"tcp://127.0.0.1:{line.split()[2]}", profile, log, BoardProfile.load(profile).channels[0]


def wait_until(cond, timeout=DEADLINE):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if cond():
            return
        time.sleep(0.01)
    raise AssertionError("condition not reached")


@pytest.mark.parametrize("setting", ["veab_limits_50", "veab_positive_limits"])
def test_sigterm_vents_the_dacs(tmp_path, setting):
    proc, board_url, profile, log, cal = start_unit_server(tmp_path, setting)
    p_max = SETTINGS[setting][1][1]
    try:
        with Board.connect(board_url, secret=SECRET) as brd:
            brd.set_pressure([p_max, p_max])
            wait_until(lambda: logged_codes(log) == [cal.code(p_max)] * 2)
            proc.send_signal(signal.SIGTERM)
            assert proc.wait(DEADLINE) == 0
    finally:
        proc.kill()
        proc.wait()
        proc.stdout.close()
        proc.stderr.close()
    assert logged_codes(log) == [cal.vent_code] * 2


@pytest.mark.parametrize("setting", ["veab_limits_50", "veab_positive_limits", "asymmetric"])
def test_sigkill_then_the_units_execstoppost_vents_the_dacs(tmp_path, setting):
    """SIGKILL leaves the DACs at their last code (the server cannot vent); the unit's ExecStopPost command,
    run as systemd runs it after any end of the service, writes the 0 kPa codes."""
    proc, board_url, profile, log, cal = start_unit_server(tmp_path, setting)
    p_max = SETTINGS[setting][1][1]
    try:
        with Board.connect(board_url, secret=SECRET, keepalive=False) as brd:
            brd.set_pressure([p_max, p_max])
            wait_until(lambda: logged_codes(log) == [cal.code(p_max)] * 2)
            proc.send_signal(signal.SIGKILL)
            proc.wait(DEADLINE)
    finally:
        proc.kill()
        proc.wait()
        proc.stdout.close()
        proc.stderr.close()
    assert logged_codes(log) == [cal.code(p_max)] * 2, "killed: still pressurized"
    argv = unit_command("ExecStopPost", profile)
    assert argv[1:3] == ["-m", "sorocontrol.vent"]
    r = subprocess.run(argv, capture_output=True, text=True, timeout=60, env=stub_env(log, SETTINGS[setting][0]))
    assert r.returncode == 0, r.stderr
    assert logged_codes(log) == [cal.vent_code] * 2
    assert f"{DACS[0]:#x}={cal.vent_code}" in r.stdout


def test_vent_command_eeprom_and_errors(tmp_path):
    profile = write_profile(tmp_path / "profile.toml", (-100e3, 100e3))
    log = tmp_path / "i2c.log"
    log.write_text("")
    env = stub_env(log, (-100e3, 100e3))
    r = subprocess.run([sys.executable, "-m", "sorocontrol.vent", "--profile", str(profile), "--eeprom"],
                       capture_output=True, text=True, timeout=60, env=env)
    assert r.returncode == 0, r.stderr
    assert [ln.split() for ln in log.read_text().splitlines()] == [
        ["96", "2048"], ["97", "2048"], ["96", "2048", "e"], ["97", "2048", "e"]]
    r = subprocess.run([sys.executable, "-m", "sorocontrol.vent", "--profile", str(tmp_path / "none.toml")],
                       capture_output=True, text=True, timeout=60, env=env)
    assert r.returncode == 2 and "does not exist" in r.stderr and "Traceback" not in r.stderr


def test_the_unit_binds_a_configured_address_and_has_the_fail_safes():
    text = UNIT.read_text()
    start = " ".join(unit_command("ExecStart", "P"))
    assert "0.0.0.0" not in start and "--host ${SORO_BOARD_HOST}" in start
    assert "--profile P" in start and " ".join(unit_command("ExecStopPost", "P")).endswith("--profile P")
    for line in ("Type=notify", "WatchdogSec=", "Restart=always", "EnvironmentFile=/etc/soro-board/board.env"):
        assert line in text
    r = subprocess.run([sys.executable, "-m", "sorocontrol.server", "--driver", "mock", "--host", "",
                        "--secret", SECRET], capture_output=True, text=True, timeout=60)
    assert r.returncode != 0 and "SORO_BOARD_HOST" in r.stderr and "Traceback" not in r.stderr


def test_the_server_pets_systemds_watchdog_and_stops_when_hung(tmp_path):
    """With NOTIFY_SOCKET and WATCHDOG_USEC set (as systemd does for Type=notify, WatchdogSec=), the server
    says READY=1 and pets WATCHDOG=1; stopped (SIGSTOP, a hung server) it pets no more, so systemd would kill
    it, run ExecStopPost and restart it."""
    path = tmp_path / "notify"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(path))
    sock.settimeout(DEADLINE)
    env = dict(os.environ, NOTIFY_SOCKET=str(path), WATCHDOG_USEC="200000", SORO_BOARD_SECRET=SECRET)
    proc = subprocess.Popen([sys.executable, "-m", "sorocontrol.server", "--driver", "mock", "--port", "0",
                             "--channels", "1"], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=env)
    try:
        got = [sock.recv(256).decode() for _ in range(3)]
        assert got[0] == "READY=1" and got[1:] == ["WATCHDOG=1", "WATCHDOG=1"]
        proc.send_signal(signal.SIGSTOP)
        time.sleep(0.1)
        sock.settimeout(0.01)
        try:
            while sock.recv(256):      # drain what was sent before the stop
                pass
        except socket.timeout:
            pass
        sock.settimeout(1.0)            # 20 petting periods of 50 ms
        with pytest.raises(socket.timeout):
            sock.recv(256)
        proc.send_signal(signal.SIGCONT)
        sock.settimeout(DEADLINE)
        assert sock.recv(256) == b"WATCHDOG=1"
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(DEADLINE) == 0
        while sock.recv(256) != b"STOPPING=1":      # a timeout here fails the test
            pass
    finally:
        proc.kill()
        proc.wait()
        proc.stdout.close()
        sock.close()
