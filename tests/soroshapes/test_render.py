"""Tube geometry and PNG rendering of :mod:`soroshapes.render`.

Geometry is checked against its definition (every tube point at exactly ``radius`` from its backbone point,
in the plane normal to the tangent); images are read back with ``matplotlib.image.imread``.
"""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from sorofem.errors import DataError, ParameterError
from soroshapes import render


def _rx(phi):
    c, s = np.cos(phi), np.sin(phi)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def helix_frames(n=40, a=0.03, b=0.01, turns=1.5, twist=2.0):
    """Poses along the helix p(t) = (a cos t, a sin t, b t) (m): Frenet frame [T, N, B] then a roll about T."""
    t = np.linspace(0.0, 2 * np.pi * turns, n)
    g = np.tile(np.eye(4), (n, 1, 1))
    for i, ti in enumerate(t):
        T = np.array([-a * np.sin(ti), a * np.cos(ti), b]) / np.hypot(a, b)
        N = np.array([-np.cos(ti), -np.sin(ti), 0.0])
        g[i, :3, :3] = np.column_stack([T, N, np.cross(T, N)]) @ _rx(twist * ti)
        g[i, :3, 3] = [a * np.cos(ti), a * np.sin(ti), b * ti]
    return g


def straight_frames(n=10, length=0.08):
    g = np.tile(np.eye(4), (n, 1, 1))
    g[:, 0, 3] = np.linspace(0.0, length, n)
    return g


# ------------------------------------------------------------------------------------------------ geometry
def test_helix_frames_are_rotations():
    R = helix_frames()[:, :3, :3]
    np.testing.assert_allclose(np.einsum("nki,nkj->nij", R, R), np.broadcast_to(np.eye(3), R.shape), atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-14)


@pytest.mark.parametrize("radius", [0.004, "tapered"])
@pytest.mark.parametrize("n_around", [3, 16, 33])
def test_tube_points_at_radius_in_normal_plane(radius, n_around):
    g = helix_frames()
    r = np.linspace(0.006, 0.002, len(g)) if radius == "tapered" else np.full(len(g), radius)
    X, Y, Z = render.tube_surface(g, r if radius == "tapered" else radius, n_around=n_around)
    assert X.shape == Y.shape == Z.shape == (len(g), n_around + 1)
    d = np.stack([X, Y, Z], axis=-1) - g[:, None, :3, 3]             # (N, M, 3) offsets from the backbone
    np.testing.assert_allclose(np.linalg.norm(d, axis=-1), r[:, None] * np.ones(n_around + 1), rtol=1e-13)
    tangent = g[:, :3, 0]
    np.testing.assert_allclose(np.einsum("nmk,nk->nm", d, tangent), 0.0, atol=1e-16)
    # the angle parameter starts on the body y axis and turns towards body z
    np.testing.assert_allclose(d[:, 0], r[:, None] * g[:, :3, 1], atol=1e-16)
    k = n_around // 4 if n_around % 4 == 0 else None
    if k:
        np.testing.assert_allclose(d[:, k], r[:, None] * g[:, :3, 2], atol=1e-16)
    # closed: last column equals the first exactly; columns evenly spaced in angle
    for C in (X, Y, Z):
        np.testing.assert_array_equal(C[:, -1], C[:, 0])
    cosang = np.einsum("nmk,nmk->nm", d[:, :-1], d[:, 1:]) / r[:, None] ** 2
    np.testing.assert_allclose(cosang, np.cos(2 * np.pi / n_around), atol=1e-12)


def test_straight_rod_tube_is_a_cylinder():
    g = straight_frames(n=7, length=0.05)
    X, Y, Z = render.tube_surface(g, 0.003, n_around=12)
    np.testing.assert_allclose(Y ** 2 + Z ** 2, 0.003 ** 2, rtol=1e-13)
    np.testing.assert_allclose(X, np.linspace(0.0, 0.05, 7)[:, None] * np.ones(13), atol=1e-17)
    a = np.arctan2(Z[0, :-1], Y[0, :-1]) % (2 * np.pi)
    np.testing.assert_allclose(a, 2 * np.pi * np.arange(12) / 12, atol=1e-13)
    np.testing.assert_array_equal(Y, np.broadcast_to(Y[0], Y.shape))  # every section the same circle


# ------------------------------------------------------------------------------------------------ validation
def test_bad_frames_raise_named_errors():
    g = helix_frames(n=6)
    with pytest.raises(ParameterError, match=r"\(N, 4, 4\)"):
        render.tube_surface(g[:, :3, :3], 0.01)
    with pytest.raises(ParameterError, match="at least 2"):
        render.tube_surface(g[:1], 0.01)
    bad = g.copy()
    bad[3, 1, 3] = np.nan
    bad[5, 0, 0] = np.inf
    with pytest.raises(DataError, match="frame 3"):
        render.tube_surface(bad, 0.01)
    skew = g.copy()
    skew[2, :3, :3] *= 1.1
    with pytest.raises(ParameterError, match="frame 2.*orthonormal"):
        render.tube_surface(skew, 0.01)


@pytest.mark.parametrize("radius, match", [(0.0, "positive"), (-1e-3, "positive"), (np.nan, "positive"),
                                           ([0.01, 0.01], r"shape \(6,\)"),
                                           (np.r_[np.full(5, 0.01), 0.0], "frame 5")])
def test_bad_radius_raises_parameter_error(radius, match):
    with pytest.raises(ParameterError, match=match):
        render.tube_surface(helix_frames(n=6), radius)


@pytest.mark.parametrize("n_around", [2, 0, 3.5, True])
def test_bad_n_around(n_around):
    with pytest.raises(ParameterError, match="n_around"):
        render.tube_surface(helix_frames(n=6), 0.01, n_around=n_around)


def test_beam_without_frames_or_radius_is_named():
    with pytest.raises(ParameterError, match="beam 1 has no 'radius'"):
        render.render_png("unused.png", [{"frames": helix_frames(), "radius": 0.01}, {"frames": helix_frames()}])
    with pytest.raises(ParameterError, match="beam 0 .*no attribute 'frames'"):
        render.render_png("unused.png", [object()])
    assert not os.path.exists("unused.png")


# ------------------------------------------------------------------------------------------------ drawing
class Beam:
    """An object-style beam (as a model class would expose it)."""

    def __init__(self, frames, radius, color=None):
        self.frames, self.radius, self.color = frames, radius, color


def test_plot_beams_returns_its_artists_in_mm():
    from matplotlib.figure import Figure
    from mpl_toolkits.mplot3d.art3d import Line3D, Line3DCollection, Poly3DCollection

    ax = Figure().add_subplot(projection="3d")
    g = helix_frames(n=21)
    beams = [{"frames": g, "radius": 0.004}, Beam(straight_frames(), 0.002, color="tab:green")]
    artists = render.plot_beams(ax, beams, frames_every=5)
    kinds = [type(a) for a in artists]
    assert kinds.count(Poly3DCollection) == 2 and kinds.count(Line3D) == 2
    assert kinds.count(Line3DCollection) == 6                           # x, y, z triads of each beam
    line = next(a for a in artists if isinstance(a, Line3D))
    np.testing.assert_allclose(np.array(line.get_data_3d()).T, 1e3 * g[:, :3, 3])  # drawn in mm
    triad = next(a for a in artists if isinstance(a, Line3DCollection))
    assert len(triad._segments3d) == 5                                 # frames 0, 5, 10, 15, 20
    assert render.plot_beams(ax, beams, backbone=False, tube=False) == []
    with pytest.raises(ParameterError, match="frames_every"):
        render.plot_beams(ax, beams, frames_every=-1)
    with pytest.raises(ParameterError, match="one per beam"):
        render.plot_beams(ax, beams, color=["r", "g", "b"])
    with pytest.raises(ParameterError, match="alpha"):
        render.plot_beams(ax, beams, alpha=2.0)


def _image(path):
    from matplotlib.image import imread

    return imread(path)


SCENE = [{"frames": helix_frames(), "radius": np.linspace(0.006, 0.003, 40)},
         Beam(straight_frames(), 0.004, color="tab:orange")]


def test_render_png_writes_a_nontrivial_image_atomically(tmp_path):
    out = render.render_png(tmp_path / "scene.png", SCENE, size=(4, 3), dpi=50, frames_every=8,
                            title="helix", obstacles=[{"type": "sphere", "center": (0.05, 0, 0), "radius": 0.01},
                                                      {"type": "plane", "point": (0, 0, -0.01),
                                                       "normal": (0, 0, 2), "size": 0.1},
                                                      {"type": "points", "xyz": np.zeros((3, 3))}])
    assert out == tmp_path / "scene.png"
    assert sorted(os.listdir(tmp_path)) == ["scene.png"]                  # no temp file left
    img = _image(out)
    assert img.shape[:2] == (3 * 50, 4 * 50)
    assert img[..., :3].std() > 0.05                                       # not a uniform image
    # the tube changes the picture (tube=False draws only the backbone lines)
    lines = _image(render.render_png(tmp_path / "lines.png", SCENE, size=(4, 3), dpi=50, tube=False))
    tubes = _image(render.render_png(tmp_path / "tubes.png", SCENE, size=(4, 3), dpi=50))
    assert np.abs(tubes - lines).mean() > 0.01


def test_render_png_equal_aspect_and_limits(tmp_path, monkeypatch):
    from mpl_toolkits.mplot3d import Axes3D

    seen = {}
    original = Axes3D.set_box_aspect

    def spy(self, aspect, **kw):
        seen["aspect"] = np.asarray(aspect, dtype=float)
        seen["limits"] = np.array([self.get_xlim(), self.get_ylim(), self.get_zlim()])
        return original(self, aspect, **kw)

    monkeypatch.setattr(Axes3D, "set_box_aspect", spy)
    g = straight_frames(length=0.1)                                       # 100 mm long, 2 x 2 mm section
    render.render_png(tmp_path / "a.png", [{"frames": g, "radius": 0.001}], size=(3, 3), dpi=40)
    span = seen["limits"][:, 1] - seen["limits"][:, 0]
    np.testing.assert_allclose(seen["aspect"], span)                     # same scale on the three axes
    np.testing.assert_allclose(span, [102.0, 5.1, 5.1])                  # mm; thin sides widened to 5 %
    render.render_png(tmp_path / "b.png", [{"frames": g, "radius": 0.001}], size=(3, 3), dpi=40,
                      limits=((0, 0.1), (-0.05, 0.05), (-0.02, 0.02)))
    np.testing.assert_allclose(seen["limits"], [[0, 100], [-50, 50], [-20, 20]])
    np.testing.assert_allclose(seen["aspect"], [100, 100, 40])


@pytest.mark.parametrize("obstacle, match", [
    ({"type": "cube", "center": (0, 0, 0)}, "known types"),
    ({"type": "sphere", "center": (0, 0, 0)}, "missing \\['radius'\\]"),
    ({"type": "sphere", "centre": (0, 0, 0), "radius": 0.01}, "unknown \\['centre'\\]"),
    ({"type": "sphere", "center": (0, 0), "radius": 0.01}, "center"),
    ({"type": "sphere", "center": (0, 0, 0), "radius": -1}, "radius"),
    ({"type": "plane", "point": (0, 0, 0), "normal": (0, 0, 0), "size": 1}, "zero vector"),
    ({"type": "points", "xyz": np.zeros((4, 2))}, r"\(m, 3\)"),
    ({"type": "points", "xyz": np.zeros((4, 3)), "color": "nope"}, "colour"),
    ({"type": "points", "xyz": np.zeros((4, 3)), "alpha": 3}, "alpha"),
])
def test_bad_obstacle_raises_before_any_file_or_directory(tmp_path, obstacle, match):
    target = tmp_path / "sub" / "x.png"
    with pytest.raises(ParameterError, match=match):
        render.render_png(target, SCENE, obstacles=[obstacle])
    assert not (tmp_path / "sub").exists()


def test_bad_options_raise_before_any_file(tmp_path):
    for kw in ({"limits": ((0, 1), (0, 1))}, {"limits": ((1, 0), (0, 1), (0, 1))}, {"size": (0, 3)},
               {"dpi": -5}, {"view": (1,)}, {"colour": "r"}, {"color": "not-a-colour"}, {"alpha": -0.1}):
        with pytest.raises(ParameterError):
            render.render_png(tmp_path / "x.png", SCENE, **kw)
    bad = helix_frames()
    bad[7, 2, 3] = np.inf
    with pytest.raises(DataError, match="beam 1 frames: frame 7"):
        render.render_png(tmp_path / "x.png", [SCENE[0], {"frames": bad, "radius": 0.01}])
    assert os.listdir(tmp_path) == []


def test_failed_save_leaves_previous_file_and_no_temp(tmp_path, monkeypatch):
    from matplotlib.figure import Figure

    out = render.render_png(tmp_path / "a.png", SCENE, size=(2, 2), dpi=30)
    before = out.read_bytes()

    written = []

    def boom(self, fname, *args, **kwargs):
        written.append(fname)
        raise OSError("disk full")

    monkeypatch.setattr(Figure, "savefig", boom)
    with pytest.raises(OSError, match="disk full"):
        render.render_png(out, SCENE[:1], size=(2, 2), dpi=30)
    assert os.listdir(tmp_path) == ["a.png"]
    assert out.read_bytes() == before
    # the figure went to a temporary file next to the destination, not onto it
    assert len(written) == 1 and written[0].parent == tmp_path and written[0].name != "a.png"


def test_render_frames_numbered_same_size_and_validated_first(tmp_path):
    seq = []
    for k in range(3):
        g = helix_frames(n=12, turns=0.5 + 0.5 * k)
        seq.append([{"frames": g, "radius": 0.004}])
    paths = render.render_frames(tmp_path / "anim", seq, size=(2, 2), dpi=30, view=(20, 30))
    assert [p.name for p in paths] == ["frame_0000.png", "frame_0001.png", "frame_0002.png"]
    assert sorted(os.listdir(tmp_path / "anim")) == [p.name for p in paths]
    shapes = {_image(p).shape for p in paths}
    assert shapes == {(60, 60, 4)}
    bad = helix_frames(n=12)
    bad[0, 0, 0] = np.nan
    with pytest.raises(DataError, match="sequence frame 1: beam 0 frames: frame 0"):
        render.render_frames(tmp_path / "anim2", [seq[0], [{"frames": bad, "radius": 0.004}]])
    assert not (tmp_path / "anim2").exists()


def test_render_frames_share_limits(tmp_path, monkeypatch):
    calls = []
    real = render.render_png

    def spy(path, beams, **kw):
        calls.append(np.array(kw["limits"]))
        return real(path, beams, **kw)

    monkeypatch.setattr(render, "render_png", spy)
    near = straight_frames(length=0.02)
    far = straight_frames(length=0.2)
    render.render_frames(tmp_path, [[{"frames": near, "radius": 0.002}], [{"frames": far, "radius": 0.002}]],
                         size=(2, 2), dpi=20)
    assert len(calls) == 2
    np.testing.assert_array_equal(calls[0], calls[1])
    assert calls[0][0, 1] >= 0.2                                           # holds the longer rod


def test_import_is_cheap():
    code = "import json, sys; before = set(sys.modules); import soroshapes.render; " \
           "print(json.dumps(sorted(set(sys.modules) - before)))"
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    heavy = sorted(m for m in json.loads(res.stdout) if m.split(".")[0] in ("matplotlib", "numba", "mpl_toolkits"))
    assert not heavy, f"importing soroshapes.render loaded {heavy}"
