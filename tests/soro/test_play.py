"""``soro play``: the page in a real headless Chromium against the model and the simulated-board back ends,
the scene protocol, the demo scenes, recording, and the command line's answers to bad input.

The light scene is one pressurized finger (``play_finger_scene.py``) whose static tip has a closed form, so the
browser test checks where the tip goes, not only that it moves. Deadlines are generous (20-60 s): the suite
runs on loaded machines; the latency from a slider change to the next frame drawn is measured by
``tests/benchmarks/bench_play.py``, never asserted here.
"""
import json
import socket
import subprocess
import sys
import urllib.request
from pathlib import Path

import numpy as np
import play_finger_scene as fs
import pytest
from play_browser import browser_page, require_browser, wait_for

SCENE = f"{Path(__file__).with_name('play_finger_scene.py')}:build"
TIP_TOL = 1e-4   # [m] settled tip vs closed form: the 3 Chebyshev modes hold a constant curvature exactly, the
                 # Magnus integration of a constant strain is exact; what is left is the settling (damped, 20 s)


def _cmd(url, **cmd):
    req = urllib.request.Request(url + "cmd", data=json.dumps(cmd).encode(), method="POST")
    try:
        return json.load(urllib.request.urlopen(req, timeout=10))
    except urllib.error.HTTPError as e:
        return json.load(e)


def _state(url):
    return json.load(urllib.request.urlopen(url + "state", timeout=10))


@pytest.fixture
def finger_server(tmp_path):
    from soro.play import load_scene, serve
    srv = serve(load_scene(SCENE), "model", port=0, out=tmp_path / "play")
    yield srv
    srv.close()


def _dist(a, b):
    return float(np.linalg.norm(np.subtract(a, b)))


def test_browser_slider_moves_the_tip_and_the_tip_follows_the_dragged_target(finger_server, tmp_path):
    require_browser()
    ref = fs.static_tip(finger_server.scene.system, fs.P_MAX)
    with browser_page(tmp_path / "chromium") as page:
        page.goto(finger_server.url)
        wait_for(page, "window.soroPlay && soroPlay.framesDrawn > 2", what="the page draws frames")
        z0 = page.evaluate("soroPlay.frame.tip[2]")
        assert abs(z0) < 1e-9                                   # straight at 0 Pa
        page.locator("#ch0").focus()
        page.keyboard.press("End")                              # the pressure slider to its maximum, 60 kPa
        wait_for(page, f"soroPlay.frame.inputs[0] === {fs.P_MAX} && soroPlay.frame.tip[2] < {z0 - 1e-3}",
                 what="the tip moves away from the chamber (-z) once the pressure arrives")
        wait_for(page, f"Math.hypot(...soroPlay.frame.tip.map((v, i) => v - {[float(v) for v in ref]}[i])) < {TIP_TOL}",
                 what=f"the tip settles at the closed-form {ref} m")
        assert page.evaluate("soroPlay.latencies.length") >= 1  # the slider's change came back in a drawn frame
        wait_for(page, "document.getElementById('source').textContent.includes('the model')", timeout=60,
                 what="the page says its 3D view is the model")
        # drag the IK target (drawn at the straight tip) to a reachable point of the bending plane
        goal = [0.045, 0.0, 0.025]
        x0, y0 = page.evaluate("soroPlay.clientOf(soroPlay.frame.target)")
        x1, y1 = page.evaluate(f"soroPlay.clientOf({goal})")
        page.mouse.move(x0, y0)
        page.mouse.down()
        page.mouse.move(x1, y1, steps=12)
        page.mouse.up()
        wait_for(page, "soroPlay.dragTarget !== undefined", what="the drag moves the target")
        wait_for(page, "soroPlay.frame.mode === 'ik' && soroPlay.frame.target.every((v, i) => "
                 "Math.abs(v - soroPlay.dragTarget[i]) < 1e-12) && "
                 "Math.hypot(...soroPlay.frame.tip.map((v, i) => v - soroPlay.frame.target[i])) < 0.002",
                 what="the tip follows the dragged target to within 2 mm")
        target = page.evaluate("soroPlay.dragTarget")
        assert _dist(target, goal) < 1e-3                       # the target went where the mouse went (~0.2 mm/px)
        assert abs(target[1]) < 1e-12                           # dragged in the screen plane: y = 0 in this view
        assert page.evaluate("soroPlay.frame.ik_error") < 1e-6  # reachable: the IK converged


def test_browser_simulated_board_receives_the_slider_and_closing_the_page_vents_it(tmp_path):
    """The slider reaches the simulated board and closing the page vents it. (Under load this once dropped the
    connection after the slider's jump: the simulated beam's step, growing with the board loop's delay,
    stalled the server past its watchdog. The plant's step is now bounded and the watchdog counts the
    client's silence only: tests/sorocontrol/test_board.py stalls a board loop on purpose.)"""
    _board_session(tmp_path)


def _board_session(tmp_path):
    require_browser()
    from soro.play import load_scene, serve
    from sorocontrol.protocol import Flag
    srv = serve(load_scene(SCENE), "sim", port=0, out=tmp_path / "play")
    board = srv.backend.board
    from soro.play.backends import SIM_WATCHDOG
    assert board.watchdog == SIM_WATCHDOG       # the simulated board behind the page (a real one keeps its own)
    try:
        with browser_page(tmp_path / "chromium") as page:
            page.goto(srv.url)
            wait_for(page, "window.soroPlay && soroPlay.framesDrawn > 2", timeout=60, what="the page draws frames")
            wait_for(page, "document.getElementById('source').textContent.includes(\"estimated from the board's sensors\")",
                     timeout=60, what="the page says its 3D view is the shape estimated from the board's sensors")
            page.locator("#ch0").focus()
            page.keyboard.press("End")
            import time
            deadline = time.monotonic() + 20
            while time.monotonic() < deadline:
                st = board.read()                               # read back from the board itself
                if st.requested[0] == fs.P_MAX and abs(st.measured[0] - fs.P_MAX) < 0.02 * fs.P_MAX:
                    break
                time.sleep(0.05)
            assert st.requested[0] == fs.P_MAX, f"the board never got the slider's {fs.P_MAX} Pa: {st}"
            assert abs(st.measured[0] - fs.P_MAX) < 0.02 * fs.P_MAX    # its regulator reached it
            wait_for(page, "soroPlay.frame.tip[2] < -1e-3", what="the sensed tip moves away from the chamber")
            page.close()                                        # the page goes: the board vents
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:
            st = board.read()
            if st.requested[0] == 0 and st.flagged(Flag.VENTED).size:
                break
            time.sleep(0.05)
        assert st.requested[0] == 0 and 0 in st.flagged(Flag.VENTED), f"closing the page did not vent: {st}"
        assert abs(st.measured[0]) < 1e3
        for _ in range(10):                                     # and it stays vented (no set-point is re-sent)
            assert board.read().requested[0] == 0
            time.sleep(0.05)
    finally:
        srv.close()
    assert board.server_process is None                         # closing the server vented and released it


def test_commands_recording_replay_and_bad_commands(finger_server, tmp_path):
    url = finger_server.url
    assert _cmd(url, type="input", name="chamber", value=30e3, seq=1)["ok"]
    assert _cmd(url, type="record")["ok"]
    srv = finger_server
    f = srv.backend.wait_frame(srv.backend.frame()["seq"] + 10, 20)
    assert f is not None and f["recording"]
    answer = _cmd(url, type="stop_record")
    path = Path(answer["path"])
    assert path.parent == tmp_path / "play" and path.is_file() and path.with_suffix(".npz").is_file()
    rows = np.genfromtxt(path, delimiter=",", names=True)
    assert rows.dtype.names == ("t_s", "chamber_Pa", "tip_x_m", "tip_y_m", "tip_z_m")
    assert np.all(rows["chamber_Pa"] == 30e3) and np.all(np.diff(rows["t_s"]) >= 0)
    assert _cmd(url, type="replay")["ok"]
    f = srv.backend.wait_frame(srv.backend.frame()["seq"] + 3, 20)
    assert f["replaying"] and f["inputs"] == [30e3] and f["t"] < rows["t_s"][-1] - rows["t_s"][0] + 0.5
    assert _cmd(url, type="input", name="chamber", value=1e9)["ok"]       # clipped to the channel's limits
    assert srv.backend.u[0] == fs.P_MAX                                   # and the slider ends the replay
    f = srv.backend.wait_frame(srv.backend.frame()["seq"] + 3, 20)
    assert not f["replaying"] and f["inputs"] == [fs.P_MAX] and "replay stopped" in f["message"]
    bad = _cmd(url, type="input", name="nope", value=1.0)
    assert not bad["ok"] and "no channel 'nope'" in bad["error"] and "chamber" in bad["error"]
    assert "unknown command" in _cmd(url, type="explode")["error"]
    assert "3 finite numbers" in _cmd(url, type="target", position=[1, 2])["error"]
    assert _cmd(url, type="pause")["ok"] and _cmd(url, type="reset")["ok"]
    f = srv.backend.wait_frame(srv.backend.frame()["seq"], 20)
    assert f["paused"] and f["inputs"] == [0.0]


def test_model_backend_reports_the_achieved_factor_and_keeps_publishing_when_slow(tmp_path):
    """An injected clock makes every step look 4x slower than real time: frames keep coming and the factor
    the page shows drops well below 1."""
    from soro.play import load_scene
    from soro.play.backends import ModelBackend
    scn = load_scene(SCENE)
    fake = {"t": 0.0}
    be = ModelBackend(scn, clock=lambda: fake["t"], out=tmp_path)
    real_step = be.plant.step

    def slow_step(h, u):
        real_step(h, u)
        fake["t"] += 4 * h                  # the wall clock advances four times the model time
    be.plant.step = slow_step
    be.start()
    try:
        f = be.wait_frame(0, 20)
        for _ in range(300):                # ~10 s of the fake wall clock: the 1 s smoothing has settled
            f = be.wait_frame(f["seq"], 20)
        assert f is not None and f["t"] > 0
        assert 0.2 < f["rtf"] < 0.3                             # 1/4, smoothed
    finally:
        be.close()


def test_scene_protocol_errors():
    from soro.play import Channel, Scene, SceneError
    from soro.play.scene import as_scene
    with pytest.raises(SceneError, match="soroshapes.Shapes or soroshapes.Model"):
        as_scene(42)
    shp = fs.finger()
    with pytest.raises(SceneError, match="not an input.*chamber"):
        Scene(shp, [Channel("valve", 0.0, 1.0)])
    with pytest.raises(ValueError, match="low < high"):
        Channel("chamber", 1.0, 0.0)
    assert [c.name for c in Scene(shp).channels] == ["chamber"]       # default channel per input
    assert Scene(shp).channels[0].high == 100e3


@pytest.mark.parametrize("name", ["soft_hand", "jellyfish_gripper", "pcc_arm", "wavy_wall", "manipulator_pick",
                                  "suzumori_gripper", "board_pick_place", "robot:bending_actuator",
                                  "robot:planar_actuator", "robot:hand", "robot:manipulator"])
def test_demo_scenes_build_and_step(name):
    from soro.play import load_scene
    from soro.play.backends import ModelBackend, scene_geometry
    scn = load_scene(name, quick=True)
    geo = json.loads(json.dumps(scene_geometry(scn)))
    assert geo["beams"] and all(len(b["outline"]) >= 8 for b in geo["beams"])
    be = ModelBackend(scn)
    u = np.array([0.5 * (c.low + c.high) for c in scn.channels])
    be.plant.step(2 * scn.dt, u)
    f = json.loads(json.dumps(be._compose(0)))
    assert f["t"] == pytest.approx(2 * scn.dt)
    assert all(np.isfinite(np.array(b["p"])).all() for b in f["beams"])
    assert len(f["beams"]) == len(scn.beam_names)


def test_robot_scenes_take_the_board_channels_limits():
    """``soro play robot:NAME``: one slider per chamber input, limited to its board channel's safety limits (the
    seed's ranges: the manipulator -10..30 kPa, its gripper -30..60 kPa on each of the three fingers)."""
    from soro.play.scene import SceneNotFoundError, load_scene
    scn = load_scene("robot:manipulator")
    limits = {c.name: (c.low, c.high) for c in scn.channels}
    assert sorted(v for k, v in limits.items() if "gripper" in k) == [(-30e3, 60e3)] * 3
    assert sorted(v for k, v in limits.items() if "gripper" not in k) == [(-10e3, 30e3)] * 3
    assert set(limits) == set(scn.system.inputs)
    with pytest.raises(SceneNotFoundError, match="bending_actuator"):
        load_scene("robot:nonexistent")


def _play(*args, timeout=120):
    return subprocess.run([sys.executable, "-m", "soro.cli", "play", *args], capture_output=True, text=True,
                          timeout=timeout)


def test_cli_missing_scene_exit_2():
    r = _play("no/such/scene.py:build", "--port", "0")
    assert r.returncode == 2
    assert "does not exist" in r.stderr and "path/to/file.py:func" in r.stderr
    r = _play("no_such_demo", "--port", "0")
    assert r.returncode == 2 and "not a demo" in r.stderr and "soft_hand" in r.stderr
    r = _play(f"{SCENE.rsplit(':', 1)[0]}:nope", "--port", "0")
    assert r.returncode == 2 and "has no function 'nope'" in r.stderr


def test_cli_scene_that_raises_exit_3():
    r = _play(f"{SCENE.rsplit(':', 1)[0]}:raises", "--port", "0")
    assert r.returncode == 3
    assert "raised RuntimeError: this scene is broken on purpose" in r.stderr
    assert "Traceback" not in r.stderr


def test_cli_port_in_use_exit_4_and_a_normal_run():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        r = _play(SCENE, "--port", str(port))
    assert r.returncode == 4
    assert f"port {port} on 127.0.0.1 is in use" in r.stderr and "--port" in r.stderr
    r = _play(SCENE, "--port", "0", "--duration", "0.5")
    assert r.returncode == 0, r.stderr
    assert "finger (model back end) at http://127.0.0.1:" in r.stdout and "stopped" in r.stdout


def _finger_env(**kw):
    pytest.importorskip("gymnasium", reason="gymnasium is not installed: run scripts/bootstrap.sh")
    from soroshapes import Model
    from soroshapes.gym import ModelEnv
    mdl = Model().add(fs.finger(), "finger")
    return ModelEnv(mdl, observation=lambda m: m["finger"].x, reward=lambda m, a: 0.0, dt=0.05, horizon=20,
                    action_inputs=["finger.chamber"], action_low=0.0, action_high=fs.P_MAX, **kw)


def test_gym_rgb_array_renders_the_beam_offscreen():
    env = _finger_env(render_mode="rgb_array", render_options={"size": (3, 3), "dpi": 60,
                                                                "limits": ((-0.01, 0.07), (-0.04, 0.04), (-0.05, 0.03))})
    env.reset(seed=0)
    a = env.render()
    assert a.dtype == np.uint8 and a.shape == (180, 180, 3)
    for _ in range(6):
        env.step(np.array([fs.P_MAX]))
    b = env.render()
    assert b.shape == a.shape and (a.astype(int) - b).any()      # the bent finger draws differently
    assert (b < 200).any(axis=-1).sum() > 100                    # and something is drawn
    with pytest.raises(ValueError, match="render_mode must be"):
        _finger_env(render_mode="window")


def test_gym_human_serves_the_page_with_the_env_state():
    env = _finger_env(render_mode="human")
    try:
        env.reset(seed=0)
        for _ in range(4):
            env.step(np.array([fs.P_MAX]))
        assert env.render() is None
        url = env.render_url
        assert url.startswith("http://127.0.0.1:")
        f = _state(url)
        shp, x = env.model["finger"].system, env.model["finger"].x
        assert f["t"] == pytest.approx(env.t) and f["backend"] == "gymnasium env"
        assert np.allclose(f["beams"][0]["p"], shp.positions(x[:shp.n]), atol=2e-6)     # rounded to 1 um
        assert f["inputs"] == [fs.P_MAX]
        assert "takes no commands" in _cmd(url, type="input", name="finger.chamber", value=0.0)["error"]
    finally:
        env.close()


class _StubBoard:
    """A board that records what it is told (the stub bus of the safety tests), in the shape of
    :class:`sorocontrol.Board`: ``channels``, ``watchdog``, ``read``, ``set_pressure``, ``vent``, ``close``."""

    channels, watchdog = 1, 0.5

    def __init__(self, fail_after=None):
        self.calls, self.p, self.fail_after = [], 0.0, fail_after

    def _state(self):
        from sorocontrol.protocol import State
        z = np.array([self.p])
        return State(0.0, 0, z, z, z, np.zeros(1, dtype=int), np.zeros(0))

    def read(self):
        self.calls.append(("read",))
        return self._state()

    def set_pressure(self, values):
        if self.fail_after is not None and sum(c[0] == "set" for c in self.calls) >= self.fail_after:
            raise RuntimeError("bus error")
        self.calls.append(("set", float(values[0])))
        self.p = float(values[0])
        return self._state()

    def vent(self):
        self.calls.append(("vent",))
        self.p = 0.0
        return self._state()

    def close(self):
        self.calls.append(("close",))
        self.p = 0.0


def _wait(cond, timeout=20.0):
    import time
    t0 = time.monotonic()
    while not cond():
        assert time.monotonic() - t0 < timeout, "condition not met within the deadline"
        time.sleep(0.01)


def test_board_backend_writes_zero_when_the_page_closes_the_server_stops_or_the_loop_fails(tmp_path):
    from soro.play import load_scene
    from soro.play.backends import BoardBackend
    scn = load_scene(SCENE)
    stub = _StubBoard()
    be = BoardBackend(scn, board=stub, out=tmp_path).start()
    try:
        assert be.view_source == "prediction"           # the stub reports no shape: the model predicts it
        _wait(lambda: ("read",) in stub.calls)
        assert not any(c[0] == "set" for c in stub.calls)   # vented at start: nothing is commanded before a slider
        be.command({"type": "input", "name": "chamber", "value": 40e3, "seq": 1})
        _wait(lambda: ("set", 40e3) in stub.calls)
        be.vent()                                       # what the server does when the last page closes
        assert stub.calls[-1] == ("vent",) or ("vent",) in stub.calls
        n = len(stub.calls)
        _wait(lambda: len(stub.calls) > n + 5)
        assert all(c[0] != "set" for c in stub.calls[n:])  # and it stays vented: only reads
    finally:
        be.close()
    assert stub.calls[-1] == ("close",)                 # Board.close vents and releases it

    failing = _StubBoard(fail_after=3)
    be = BoardBackend(scn, board=failing, out=tmp_path).start()
    try:
        be.command({"type": "input", "name": "chamber", "value": 20e3, "seq": 1})
        _wait(lambda: be.frame()["message"].startswith("the back end stopped"))
        assert "RuntimeError: bus error" in be.frame()["message"] and "vented" in be.frame()["message"]
        assert failing.calls[-1] == ("vent",) and failing.p == 0.0
    finally:
        be.close()
    with pytest.raises(ValueError, match="IK target drives the model back end"):
        BoardBackend(scn, board=_StubBoard(), out=tmp_path).command({"type": "target", "position": [0, 0, 0]})


def test_board_backend_refuses_a_public_host():
    from soro.play import load_scene, serve
    with pytest.raises(ValueError, match="on this machine only"):
        serve(load_scene(SCENE), "sim", host="0.0.0.0", port=0)


def test_real_board_backend_by_url_and_secret(tmp_path):
    """The ``board`` back end over the real protocol (a BoardServer with a mock driver on loopback): the
    slider's value is the board's request, the view is the model's prediction (the driver reports no shape),
    a wrong secret is a clear error, and closing the server vents the board."""
    from soro.play import load_scene, serve
    from sorocontrol import BoardServer, MockDriver
    from sorofem.errors import ProtocolError
    secret = "5b0e9c41d7a2f3866c1e0b9d4a7f2e13"
    with BoardServer(MockDriver(1), secret, port=0) as board_srv:
        url = f"tcp://127.0.0.1:{board_srv.address[1]}"
        with pytest.raises(ProtocolError):
            serve(load_scene(SCENE), "board", port=0, board_url=url, secret="9e2d7c1a5f3b8046e7d2c9a1b5f40e37")
        import time
        time.sleep(1.0)                 # the board's back-off after a failed login (0.1 s after the first)
        srv = serve(load_scene(SCENE), "board", port=0, board_url=url, secret=secret, out=tmp_path)
        try:
            f = srv.backend.wait_frame(0, 20)
            assert f["backend"] == "board" and f["view_source"] == "prediction"
            assert _cmd(srv.url, type="input", name="chamber", value=25e3)["ok"]
            _wait(lambda: board_srv.requested[0] == 25e3)
            _wait(lambda: (srv.backend.frame()["tip"][2] < -1e-4))      # the prediction bends the finger
        finally:
            srv.close()
        _wait(lambda: board_srv.requested[0] == 0 and board_srv.applied[0] == 0)


def test_impedance_mode_brings_the_tip_to_the_target(tmp_path):
    """manipulator_pick's arm under its Cartesian impedance controller (the demo's gains): the tip settles on
    a set-point in the arm's plane, within 2 mm (gravity and elasticity are compensated, so the steady
    state is the set-point)."""
    from soro.play import load_scene
    from soro.play.backends import ModelBackend
    scn = load_scene("manipulator_pick", quick=True)
    be = ModelBackend(scn, out=tmp_path).start()
    try:
        goal = [0.08, 0.0, 0.12]
        be.command({"type": "mode", "mode": "impedance"})
        be.command({"type": "target", "position": goal})
        deadline = 120.0
        import time
        t0 = time.monotonic()
        while True:
            f = be.wait_frame(be.frame()["seq"], 20)
            if f["mode"] == "impedance" and _dist([f["tip"][0], f["tip"][2]], [goal[0], goal[2]]) < 2e-3:
                break
            assert not f["paused"], f["message"]
            assert time.monotonic() - t0 < deadline, f"the tip did not reach {goal}: {f['tip']} at t = {f['t']}"
        with pytest.raises(ValueError, match="mode must be one of"):
            be.command({"type": "mode", "mode": "dance"})
    finally:
        be.close()
    with pytest.raises(ValueError, match="mode must be one of"):      # a scene without impedance
        ModelBackend(load_scene(SCENE), out=tmp_path).command({"type": "mode", "mode": "impedance"})
