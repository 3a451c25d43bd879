r"""Render Cosserat beam backbones as shaded tubes to PNG files (matplotlib, Agg; no window ever opens).

A beam is given as data, not as a model object: anything with ``frames`` and ``radius`` (a dict with those
keys or an object with those attributes) renders, so backbones from forward kinematics, from a simulation
trajectory or from shape estimation all draw the same way.

- ``frames``: ``(N, 4, 4)`` SE(3) poses :math:`g_i = \begin{bmatrix} R_i & p_i \\ 0 & 1 \end{bmatrix}` along
  the backbone, :math:`p_i` in m. The columns of :math:`R_i` are the body axes: the backbone tangent is the
  body :math:`x` axis and the cross-section lies in the body :math:`(y, z)` plane.
- ``radius``: the tube radius in m, a float or one value per frame ``(N,)`` (tapered rods).
- optionally ``color``: a matplotlib colour for this beam.

The tube surface is :math:`x_{ij} = p_i + r_i (\cos a_j\, R_i e_2 + \sin a_j\, R_i e_3)` for
:math:`a_j = 2\pi j / n`, :math:`j = 0..n` (the last column repeats the first, so the surface is closed).

Everything is computed in metres; the **plots are labelled and drawn in millimetres** (coordinates are
multiplied by :math:`10^3` for display only). PNG files are written atomically (temporary file next to the
destination, then ``os.replace``), and all inputs are validated before any file or directory is created.
matplotlib is imported inside the functions, so importing this module is cheap.

Examples
--------
>>> import os, tempfile
>>> import numpy as np
>>> from soroshapes.render import render_png
>>> s = np.linspace(0.0, 0.08, 40)                 # arc length (m) of a rod bent into a quarter circle
>>> kappa = (np.pi / 2) / 0.08                     # curvature (1/m) about the body z axis
>>> frames = np.tile(np.eye(4), (s.size, 1, 1))
>>> c, n = np.cos(kappa * s), np.sin(kappa * s)
>>> frames[:, 0, 0], frames[:, 0, 1], frames[:, 1, 0], frames[:, 1, 1] = c, -n, n, c
>>> frames[:, 0, 3], frames[:, 1, 3] = n / kappa, (1 - c) / kappa
>>> out = render_png(os.path.join(tempfile.mkdtemp(), "arc.png"), [{"frames": frames, "radius": 0.006}])
>>> out.name, out.stat().st_size > 1000
('arc.png', True)
"""
import logging
from pathlib import Path

import numpy as np

from sorofem.errors import DataError, ParameterError
from sorofem.io import atomic_path

__all__ = ["tube_surface", "plot_beams", "render_png", "render_frames"]

logger = logging.getLogger(__name__)

DISPLAY_SCALE = 1e3
"""Factor from metres (the data) to the displayed unit, millimetres."""

_ORTHO_TOL = 1e-6  # max |R^T R - I| accepted for a frame's rotation block
_TRIAD_COLORS = ("red", "green", "blue")  # body x, y, z
_OBSTACLE_KEYS = {
    "sphere": {"center", "radius"},
    "plane": {"point", "normal", "size"},
    "points": {"xyz"},
}
_OBSTACLE_STYLE = {"color", "alpha"}
_BEAM_STYLE_KEYS = {"color", "alpha", "frames_every", "backbone", "tube"}


# ----------------------------------------------------------------------------------------------------------
# validation
# ----------------------------------------------------------------------------------------------------------
def _frames(frames, what="frames"):
    """``frames`` as a float (N, 4, 4) array of finite poses with orthonormal rotation blocks, N >= 2."""
    try:
        g = np.asarray(frames, dtype=float)
    except (TypeError, ValueError) as e:
        raise ParameterError(f"{what} must be an (N, 4, 4) array of SE(3) poses: {e}") from e
    if g.ndim != 3 or g.shape[1:] != (4, 4):
        raise ParameterError(f"{what} must be an (N, 4, 4) array of SE(3) poses, got shape {g.shape}")
    if g.shape[0] < 2:
        raise ParameterError(f"{what} holds {g.shape[0]} pose(s): a backbone needs at least 2 frames")
    finite = np.isfinite(g).all(axis=(1, 2))
    if not finite.all():
        i = int(np.argmin(finite))
        raise DataError(f"{what}: frame {i} holds a NaN or infinity (first of {int((~finite).sum())} "
                        "non-finite frames); check the kinematics or the solver that produced it")
    R = g[:, :3, :3]
    err = np.abs(np.einsum("nki,nkj->nij", R, R) - np.eye(3)).max(axis=(1, 2))
    if (err > _ORTHO_TOL).any():
        i = int(np.argmax(err > _ORTHO_TOL))
        raise ParameterError(f"{what}: the rotation block of frame {i} is not orthonormal "
                             f"(max |R^T R - I| = {err[i]:.2e} > {_ORTHO_TOL:g}); re-orthonormalize it")
    return g


def _radius(radius, n, what="radius"):
    """``radius`` (m) as a positive finite (n,) array."""
    try:
        r = np.asarray(radius, dtype=float)
    except (TypeError, ValueError) as e:
        raise ParameterError(f"{what} must be a float or an (N,) array in m: {e}") from e
    if r.ndim == 0:
        r = np.full(n, float(r))
    elif r.shape != (n,):
        raise ParameterError(f"{what} must be a float or one value per frame, shape ({n},); got {r.shape}")
    if not np.isfinite(r).all() or (r <= 0).any():
        bad = np.flatnonzero(~(np.isfinite(r) & (r > 0)))
        raise ParameterError(f"{what} must be positive and finite (m); got {r[bad[0]]!r} at frame {bad[0]}")
    return r


def _get(obj, key, what):
    if isinstance(obj, dict):
        if key not in obj:
            raise ParameterError(f"{what} has no {key!r} key; a beam needs 'frames' (N, 4, 4) and 'radius' (m)")
        return obj[key]
    if not hasattr(obj, key):
        raise ParameterError(f"{what} ({type(obj).__name__}) has no attribute {key!r}; a beam needs "
                             "'frames' (N, 4, 4) and 'radius' (m)")
    return getattr(obj, key)


def _beams(beams):
    """Validated beams: a list of (frames, radius, color or None). A single beam is accepted too."""
    if isinstance(beams, dict) or hasattr(beams, "frames"):
        beams = [beams]
    try:
        beams = list(beams)
    except TypeError as e:
        raise ParameterError(f"beams must be a list of beams (dicts or objects with 'frames' and 'radius'), "
                             f"got {type(beams).__name__}") from e
    out = []
    for k, b in enumerate(beams):
        what = f"beam {k}"
        g = _frames(_get(b, "frames", what), f"{what} frames")
        r = _radius(_get(b, "radius", what), g.shape[0], f"{what} radius")
        color = b.get("color") if isinstance(b, dict) else getattr(b, "color", None)
        out.append((g, r, color))
    return out


def _vec3(v, what):
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError) as e:
        raise ParameterError(f"{what} must be 3 numbers (m): {e}") from e
    if a.shape != (3,) or not np.isfinite(a).all():
        raise ParameterError(f"{what} must be 3 finite numbers (m), got {v!r}")
    return a


def _positive(v, what):
    try:
        x = float(v)
    except (TypeError, ValueError) as e:
        raise ParameterError(f"{what} must be a positive number (m), got {v!r}") from e
    if not np.isfinite(x) or x <= 0:
        raise ParameterError(f"{what} must be positive and finite (m), got {v!r}")
    return x


def _obstacles(obstacles):
    """Validated obstacles: a list of dicts with float arrays, ``type`` and style keys."""
    if isinstance(obstacles, dict):
        obstacles = [obstacles]
    out = []
    for k, ob in enumerate(obstacles):
        what = f"obstacle {k}"
        if not isinstance(ob, dict):
            raise ParameterError(f"{what} must be a dict with a 'type' key, got {type(ob).__name__}")
        kind = ob.get("type")
        if kind not in _OBSTACLE_KEYS:
            raise ParameterError(f"{what} has type {kind!r}; known types are {sorted(_OBSTACLE_KEYS)}")
        need = _OBSTACLE_KEYS[kind]
        missing = need - ob.keys()
        extra = ob.keys() - need - _OBSTACLE_STYLE - {"type"}
        if missing or extra:
            raise ParameterError(f"{what} ({kind}) needs keys {sorted(need)} (optional {sorted(_OBSTACLE_STYLE)}); "
                                 f"missing {sorted(missing)}, unknown {sorted(extra)}")
        v = {"type": kind, **{s: ob[s] for s in _OBSTACLE_STYLE if s in ob}}
        if "alpha" in v:
            _alpha(v["alpha"])
        if "color" in v:
            from matplotlib.colors import is_color_like

            if not is_color_like(v["color"]):
                raise ParameterError(f"{what} color {v['color']!r} is not a matplotlib colour")
        if kind == "sphere":
            v["center"] = _vec3(ob["center"], f"{what} center")
            v["radius"] = _positive(ob["radius"], f"{what} radius")
        elif kind == "plane":
            v["point"] = _vec3(ob["point"], f"{what} point")
            nrm = _vec3(ob["normal"], f"{what} normal")
            length = np.linalg.norm(nrm)
            if length == 0:
                raise ParameterError(f"{what} normal is the zero vector; give the plane's normal direction")
            v["normal"] = nrm / length
            v["size"] = _positive(ob["size"], f"{what} size")
        else:
            try:
                xyz = np.asarray(ob["xyz"], dtype=float)
            except (TypeError, ValueError) as e:
                raise ParameterError(f"{what} xyz must be an (m, 3) array (m): {e}") from e
            if xyz.ndim != 2 or xyz.shape[1] != 3:
                raise ParameterError(f"{what} xyz must be an (m, 3) array (m), got shape {xyz.shape}")
            if not np.isfinite(xyz).all():
                raise DataError(f"{what} xyz: point {int(np.argmin(np.isfinite(xyz).all(axis=1)))} "
                                "holds a NaN or infinity")
            v["xyz"] = xyz
        out.append(v)
    return out


def _alpha(alpha):
    try:
        ok = 0.0 <= float(alpha) <= 1.0
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ParameterError(f"alpha must be a number in [0, 1], got {alpha!r}")


def _style(kw):
    unknown = set(kw) - _BEAM_STYLE_KEYS
    if unknown:
        raise ParameterError(f"unknown keyword(s) {sorted(unknown)}; beam style keywords are "
                             f"{sorted(_BEAM_STYLE_KEYS)}")
    k = kw.get("frames_every", 0)
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 0:
        raise ParameterError(f"frames_every must be a non-negative integer (0: no triads), got {k!r}")
    return kw


# ----------------------------------------------------------------------------------------------------------
# geometry
# ----------------------------------------------------------------------------------------------------------
def tube_surface(frames, radius, n_around=16):
    r"""Closed tube surface around a backbone.

    Parameters
    ----------
    frames : (N, 4, 4) array_like
        SE(3) poses along the backbone (positions in m); the body x axis is the tangent, the section lies in
        the body (y, z) plane.
    radius : float or (N,) array_like
        Tube radius in m, positive.
    n_around : int
        Number of facets around the section (at least 3).

    Returns
    -------
    X, Y, Z : (N, n_around + 1) ndarray
        Coordinates in m of :math:`x_{ij} = p_i + r_i (\cos a_j R_i e_2 + \sin a_j R_i e_3)`,
        :math:`a_j = 2\pi j / n`; column ``n_around`` equals column 0 exactly, so the surface is closed.

    Raises
    ------
    ParameterError
        Bad shapes, non-orthonormal rotations, ``radius <= 0`` or ``n_around < 3``.
    DataError
        A non-finite frame (the message names its index).
    """
    g = _frames(frames)
    r = _radius(radius, g.shape[0])
    if isinstance(n_around, bool) or not isinstance(n_around, (int, np.integer)) or n_around < 3:
        raise ParameterError(f"n_around must be an integer >= 3, got {n_around!r}")
    return _tube(g, r, int(n_around))


def _tube(g, r, n_around):
    a = np.linspace(0.0, 2.0 * np.pi, n_around + 1)
    ca, sa = np.cos(a), np.sin(a)
    ca[-1], sa[-1] = 1.0, 0.0  # close the surface exactly
    e2, e3 = g[:, :3, 1], g[:, :3, 2]  # (N, 3) body y and z axes
    P = g[:, None, :3, 3] + r[:, None, None] * (ca[None, :, None] * e2[:, None, :]
                                                 + sa[None, :, None] * e3[:, None, :])
    return P[..., 0], P[..., 1], P[..., 2]


def _triad_length(g, r):
    """Length (m) of the body-axis triads: twice the largest radius, at least 5 % of the backbone length."""
    length = np.linalg.norm(np.diff(g[:, :3, 3], axis=0), axis=1).sum()
    return max(2.0 * r.max(), 0.05 * length)


def _bounds(beams, obstacles, frames_every=0):
    """(lo, hi) corners in m of a box that holds every drawn beam and obstacle, or None if there are none."""
    lo, hi = [], []
    for g, r, _ in beams:
        p = g[:, :3, 3]
        pad = _triad_length(g, r) if frames_every else r.max()
        lo.append(p.min(axis=0) - pad)
        hi.append(p.max(axis=0) + pad)
    for ob in obstacles:
        if ob["type"] == "sphere":
            lo.append(ob["center"] - ob["radius"])
            hi.append(ob["center"] + ob["radius"])
        elif ob["type"] == "plane":
            c = _plane_corners(ob)
            lo.append(c.min(axis=0))
            hi.append(c.max(axis=0))
        elif len(ob["xyz"]):
            lo.append(ob["xyz"].min(axis=0))
            hi.append(ob["xyz"].max(axis=0))
    if not lo:
        return None
    return np.min(lo, axis=0), np.max(hi, axis=0)


def _plane_basis(n):
    """Two unit vectors orthogonal to the unit vector ``n`` and to each other."""
    t = np.eye(3)[np.argmin(np.abs(n))]
    u = np.cross(n, t)
    u /= np.linalg.norm(u)
    return u, np.cross(n, u)


def _plane_corners(ob):
    u, v = _plane_basis(ob["normal"])
    h = 0.5 * ob["size"]
    return np.array([ob["point"] + h * (i * u + j * v) for i in (-1, 1) for j in (-1, 1)])


# ----------------------------------------------------------------------------------------------------------
# drawing
# ----------------------------------------------------------------------------------------------------------
def plot_beams(ax, beams, *, color=None, alpha=1.0, frames_every=0, backbone=True, tube=True):
    """Draw beams on a matplotlib 3D axes, in millimetres.

    Parameters
    ----------
    ax : mpl_toolkits.mplot3d.axes3d.Axes3D
        Target axes. Coordinates are drawn in **mm** (the data in m times 1e3).
    beams : list
        Beams: dicts or objects with ``frames`` (N, 4, 4) poses in m and ``radius`` (m, float or (N,)),
        optionally ``color``. A single beam is accepted too.
    color : color or list of colors, optional
        One colour for every beam or one per beam; a beam's own ``color`` wins. Default: the colour cycle
        (``C0``, ``C1``, ...).
    alpha : float
        Opacity of the tube surfaces, in [0, 1].
    frames_every : int
        Draw the body axes (x red, y green, z blue) of every ``frames_every``-th frame and of the last one
        as small triads (length: twice the radius, at least 5 % of the backbone length); 0 draws none.
    backbone, tube : bool
        Draw the backbone curve :math:`p(s)` as a line, the tube as a lit surface (24 facets around, light
        from the upper left).

    Returns
    -------
    list
        The artists created (``Poly3DCollection`` surfaces, ``Line3D`` backbones, ``Line3DCollection`` triads).

    Raises
    ------
    ParameterError, DataError
        As :func:`tube_surface`, naming the beam; ``ParameterError`` for bad options.
    """
    _style({"frames_every": frames_every})
    return _draw_beams(ax, _beams(beams), color=color, alpha=alpha, frames_every=frames_every,
                       backbone=backbone, tube=tube)


def _beam_colors(beams, color):
    from matplotlib.colors import is_color_like

    if color is None:
        colors = [f"C{k % 10}" for k in range(len(beams))]
    elif is_color_like(color):
        colors = [color] * len(beams)
    else:
        colors = list(color)
        if len(colors) != len(beams):
            raise ParameterError(f"color must be one colour or one per beam ({len(beams)}), got {len(colors)}")
    colors = [own if own is not None else c for (_, _, own), c in zip(beams, colors)]
    for k, c in enumerate(colors):
        if not is_color_like(c):
            raise ParameterError(f"beam {k}: {c!r} is not a matplotlib colour")
    return colors


def _draw_beams(ax, beams, *, color=None, alpha=1.0, frames_every=0, backbone=True, tube=True):
    from matplotlib.colors import LightSource, to_rgb
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    _alpha(alpha)
    colors = _beam_colors(beams, color)
    light = LightSource(azdeg=315, altdeg=45)
    s = DISPLAY_SCALE
    artists = []
    for (g, r, _), c in zip(beams, colors):
        if tube:
            X, Y, Z = _tube(g, r, 24)
            artists.append(ax.plot_surface(s * X, s * Y, s * Z, color=c, alpha=alpha, shade=True,
                                           lightsource=light, rstride=1, cstride=1, linewidth=0,
                                           antialiased=False))
        if backbone:
            p = s * g[:, :3, 3]
            dark = tuple(0.55 * x for x in to_rgb(c)) if tube else c
            artists.extend(ax.plot(p[:, 0], p[:, 1], p[:, 2], color=dark, lw=1.0 if tube else 2.0))
        if frames_every:
            idx = np.unique(np.r_[np.arange(0, g.shape[0], frames_every), g.shape[0] - 1])
            L = _triad_length(g, r)
            for axis, tc in enumerate(_TRIAD_COLORS):
                seg = np.stack([g[idx, :3, 3], g[idx, :3, 3] + L * g[idx, :3, axis]], axis=1)
                triad = Line3DCollection(s * seg, colors=tc, linewidths=1.5)
                ax.add_collection3d(triad)
                artists.append(triad)
    return artists


def _draw_obstacles(ax, obstacles):
    from matplotlib.colors import LightSource

    light = LightSource(azdeg=315, altdeg=45)
    s = DISPLAY_SCALE
    artists = []
    for ob in obstacles:
        c, a = ob.get("color", "0.6"), ob.get("alpha", None)
        if ob["type"] == "sphere":
            u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 33), np.linspace(0, np.pi, 17))
            d = np.stack([np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)], axis=-1)
            P = s * (ob["center"] + ob["radius"] * d)
            artists.append(ax.plot_surface(P[..., 0], P[..., 1], P[..., 2], color=c,
                                           alpha=0.6 if a is None else a, shade=True, lightsource=light,
                                           linewidth=0, antialiased=False))
        elif ob["type"] == "plane":
            P = s * _plane_corners(ob).reshape(2, 2, 3)
            artists.append(ax.plot_surface(P[..., 0], P[..., 1], P[..., 2], color=c,
                                           alpha=0.3 if a is None else a, shade=False, linewidth=0))
        else:
            P = s * ob["xyz"]
            artists.append(ax.scatter(P[:, 0], P[:, 1], P[:, 2], color="k" if "color" not in ob else c,
                                      alpha=1.0 if a is None else a, s=8, depthshade=False))
    return artists


def _check_limits(limits):
    try:
        lim = np.asarray(limits, dtype=float)
    except (TypeError, ValueError) as e:
        raise ParameterError(f"limits must be ((xmin, xmax), (ymin, ymax), (zmin, zmax)) in m: {e}") from e
    if lim.shape != (3, 2) or not np.isfinite(lim).all() or (lim[:, 1] <= lim[:, 0]).any():
        raise ParameterError(f"limits must be ((xmin, xmax), (ymin, ymax), (zmin, zmax)) in m with min < max, "
                             f"got {limits!r}")
    return lim


def _padded_limits(lo, hi):
    """Limits (3, 2) in m around the box [lo, hi], each side widened to at least 5 % of the largest one."""
    span = hi - lo
    side = np.maximum(span, 0.05 * span.max()) if span.max() > 0 else np.full(3, 1e-3)
    mid = 0.5 * (lo + hi)
    return np.stack([mid - 0.5 * side, mid + 0.5 * side], axis=1)


def _check_figure_args(view, size, dpi):
    try:
        elev, azim = (float(x) for x in view)
        w, h = (float(x) for x in size)
        dpi = float(dpi)
    except (TypeError, ValueError) as e:
        raise ParameterError(f"view must be (elev, azim) in degrees, size (width, height) in inches and dpi a "
                             f"number: {e}") from e
    if not (np.isfinite([elev, azim]).all() and w > 0 and h > 0 and dpi > 0 and np.isfinite([w, h, dpi]).all()):
        raise ParameterError(f"size and dpi must be positive and view finite; got view={view!r}, size={size!r}, "
                             f"dpi={dpi!r}")
    return (elev, azim), (w, h), dpi


def render_png(path, beams, *, obstacles=(), view=(25, -60), title=None, size=(6, 5), dpi=120, limits=None,
               equal=True, **style):
    """Render beams (and obstacles) to a PNG file, atomically.

    Parameters
    ----------
    path : str or Path
        Destination PNG; its parent directory is created. Written to a temporary file next to it, then renamed.
    beams : list
        Beams as in :func:`plot_beams` (frames in m, radius in m).
    obstacles : list of dict
        ``{"type": "sphere", "center": (3,), "radius": r}``, ``{"type": "plane", "point": (3,),
        "normal": (3,), "size": s}`` (a square of side ``s`` centred on ``point``) or
        ``{"type": "points", "xyz": (m, 3)}`` (a scatter); all in m. Optional ``color`` and ``alpha`` keys.
    view : (float, float)
        Camera elevation and azimuth in degrees.
    title : str, optional
        Figure title.
    size : (float, float)
        Figure size in inches; the image is ``size * dpi`` pixels.
    dpi : float
        Resolution in pixels per inch.
    limits : ((xmin, xmax), (ymin, ymax), (zmin, zmax)), optional
        Axis limits in m; default: the data bounds (tubes, obstacles, triads), a side thinner than 5 % of the
        largest widened to it.
    equal : bool
        Same scale on the three axes: the box aspect is set to the ranges of the limits. Axes are labelled
        in **mm**.
    **style
        ``color``, ``alpha``, ``frames_every``, ``backbone``, ``tube``: passed to :func:`plot_beams`.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ParameterError, DataError
        On invalid beams, obstacles or options, before any file or directory is created.
    """
    path = Path(path)
    _style(style)
    vb, ob = _beams(beams), _obstacles(obstacles)
    view, size, dpi = _check_figure_args(view, size, dpi)
    if limits is not None:
        lim = _check_limits(limits)
    else:
        box = _bounds(vb, ob, style.get("frames_every", 0))
        lim = None if box is None else _padded_limits(*box)
    _beam_colors(vb, style.get("color"))  # validate colours before creating anything
    _alpha(style.get("alpha", 1.0))

    from matplotlib.figure import Figure
    from mpl_toolkits.mplot3d import Axes3D  # noqa: F401 - registers the "3d" projection

    fig = Figure(figsize=size, dpi=dpi)
    fig.subplots_adjust(left=0.0, right=0.97, bottom=0.0, top=1.0 if title is None else 0.95)
    ax = fig.add_subplot(projection="3d")
    _draw_obstacles(ax, ob)
    _draw_beams(ax, vb, **style)
    if lim is not None:
        L = DISPLAY_SCALE * lim
        ax.set_xlim(*L[0])
        ax.set_ylim(*L[1])
        ax.set_zlim(*L[2])
        if equal:
            ax.set_box_aspect(tuple(L[:, 1] - L[:, 0]), zoom=0.9)
    ax.view_init(elev=view[0], azim=view[1])
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_zlabel("z [mm]")
    if title is not None:
        ax.set_title(str(title))
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, format="png", dpi=dpi)
    logger.debug("wrote %s", path)
    return path


def render_frames(directory, sequence, **kw):
    """Render a sequence of scenes to numbered PNGs ``frame_0000.png``, ``frame_0001.png``, ... (animations).

    Parameters
    ----------
    directory : str or Path
        Output directory, created if needed. Frames of an earlier, longer run with higher numbers are not
        removed.
    sequence : list of list of beams
        One list of beams (as in :func:`plot_beams`, in m) per frame.
    **kw
        Passed to :func:`render_png`. Unless ``limits`` is given, all frames share the limits that hold every
        frame, so the camera does not jump.

    Returns
    -------
    list of Path
        The files written, in order.

    Raises
    ------
    ParameterError, DataError
        On invalid input in any frame, before any file is written (the message names the frame).
    """
    directory = Path(directory)
    sequence = list(sequence)
    _style({k: v for k, v in kw.items() if k in _BEAM_STYLE_KEYS})
    checked = []
    for i, beams in enumerate(sequence):
        try:
            checked.append(_beams(beams))
        except (ParameterError, DataError) as e:
            raise type(e)(f"sequence frame {i}: {e}") from e
    if kw.get("limits") is None and checked:
        ob = _obstacles(kw.get("obstacles", ()))
        boxes = [b for b in (_bounds(vb, ob, kw.get("frames_every", 0)) for vb in checked) if b is not None]
        if boxes:
            lo, hi = np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)
            lim = _padded_limits(lo, hi)
            kw = {**kw, "limits": lim}
    width = max(4, len(str(len(sequence) - 1)))
    paths = []
    for i, beams in enumerate(sequence):
        paths.append(render_png(directory / f"frame_{i:0{width}d}.png", beams, **kw))
        logger.info("rendered frame %d/%d", i + 1, len(sequence))
    return paths
