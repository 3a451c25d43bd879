"""The open-hardware robots in the application layer: the designs of :mod:`sorofem.robots` (names, parameters,
printed parts; re-exported here) with what is made from them: the twins as beams and ``soro play`` scenes
(:mod:`soro.robots.twin`), the board profile (:mod:`soro.robots.board`), the full export (one binary STL per
printed part, a 3D preview PNG, the board profile ``NAME_board.toml`` and ``NAME.json``) and the ``soro robot``
command (:mod:`soro.robots.cli`).

>>> from soro import robots
>>> sorted(robots.names())
['bending_actuator', 'hand', 'manipulator', 'planar_actuator']
>>> d = robots.design("bending_actuator")          # parameters in SI: robots.design(name, wall=2.5e-3)
>>> [p.name for p in d.parts], d.channels["bend"]
(['actuator'], (-10000.0, 100000.0))

``export(name, out)`` writes one binary STL per printed part (millimetres by default, the unit in the header;
through :func:`sorofem.sdf.to_stl`), a 3D preview PNG (surface render, axes in mm), the board profile
``NAME_board.toml`` (:func:`board_profile`: one channel per network, the seed's pressure ranges as the safety
limits) and ``NAME.json`` (parameters, board channels with their pressure limits, per-part bounding box,
watertightness, shells, volume, the flood-fill check of each pneumatic network, and the twins' reduced-model
data).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from sorofem.robots import (ROBOTS, UNITS, Chamber, Design, Network, Param, Part, Robot, Twin, chamber_check, design,
                            export_part, get, names, parse_params)
from sorofem.units import mm

from .board import VEAB_SIGNAL_RANGE, board_profile
from .twin import (BELLOWS_E_FACTOR, PARALLEL_BELLOWS_E_FACTOR, ROUND_BELLOWS_E_FACTOR, Channel, Scene,
                   bellows_modulus, chain_stretch, reach, twin_shapes)
from .twin import scene as twin_scene

__all__ = ["names", "get", "design", "parse_params", "export", "export_part", "preview_png", "chamber_check",
           "board_profile", "VEAB_SIGNAL_RANGE", "Scene", "Channel", "twin_shapes", "scene",
           "reach", "chain_stretch", "bellows_modulus", "BELLOWS_E_FACTOR", "ROUND_BELLOWS_E_FACTOR",
           "PARALLEL_BELLOWS_E_FACTOR",
           "Param", "Network", "Part", "Chamber", "Twin", "Design", "Robot", "ROBOTS", "UNITS"]


def scene(name, stiffness="bellows", **params):
    """The ``soro play`` scene of robot ``name`` built with ``params`` in SI (:func:`soro.robots.twin.scene`);
    ``soro play``
    lists it as ``robot:NAME``."""
    return twin_scene(design(name, **params), stiffness=stiffness)


def _shade(tri, color):
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    light = np.array([0.4, -0.5, 0.77])
    k = 0.35 + 0.65 * np.clip(n @ (light / np.linalg.norm(light)), 0, 1)
    return np.clip(np.asarray(color)[None, :] * k[:, None], 0, 1)


_COLORS = {"Elastic80A": (0.95, 0.55, 0.2), "PLA": (0.55, 0.6, 0.7)}


def preview_png(meshes, path, title=None, view=(25, -60)):
    """A 3D surface render of triangle meshes, axes in mm, equal aspect; written atomically.

    Parameters
    ----------
    meshes : list of (triangles (F, 3, 3) [m], material name)
    path : str or Path
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    from sorofem.io import atomic_path
    fig = Figure(figsize=(8, 6.5))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1, projection="3d")
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for tri, mat in meshes:
        t = tri / mm
        lo, hi = np.minimum(lo, t.reshape(-1, 3).min(0)), np.maximum(hi, t.reshape(-1, 3).max(0))
        pc = Poly3DCollection(t, facecolors=_shade(tri, _COLORS.get(mat, (0.6, 0.6, 0.6))), linewidths=0)
        ax.add_collection3d(pc)
    c, r = (lo + hi) / 2, (hi - lo).max() / 2
    ax.set_xlim(c[0] - r, c[0] + r)
    ax.set_ylim(c[1] - r, c[1] + r)
    ax.set_zlim(c[2] - r, c[2] + r)
    ax.set_box_aspect((1, 1, 1))
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.set_zlabel("z [mm]")
    ax.view_init(*view)
    size = hi - lo
    ax.set_title((title or "") + f"\nbounding box {size[0]:.0f} x {size[1]:.0f} x {size[2]:.0f} mm", fontsize=10)
    fig.tight_layout()
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    return Path(path)


def export(name, out, units="mm", params=None, resolution=None, preview=True, check=True):
    """Export robot ``name``: ``NAME_PART.stl`` per printed part, ``NAME.png``, ``NAME_board.toml`` (the board
    profile) and ``NAME.json`` in ``out``.

    Parameters
    ----------
    name : str
    out : str or Path
        Output directory (created).
    units : str
        Length unit of the STL files (default ``"mm"``, what slicers read).
    params : dict, optional
        Design parameters in SI (see :func:`parse_params` for command-line strings).
    resolution : float, optional
        Marching-cubes grid step [m] (default a third of each part's smallest feature).
    preview, check : bool
        Write the PNG; run the flood fill of each network.

    Returns
    -------
    dict
        The report written to ``NAME.json``.
    """
    from sorofem.io import atomic_path, write_json
    from sorofem.sdf import surface_check
    out = Path(out)
    dsg = design(name, **(params or {}))
    robot = get(name)
    report = {"robot": name, "title": robot.title, "units": units,
              "params": {p.name: dsg.params[p.name] / UNITS[p.unit] for p in robot.PARAMS},
              "param_units": {p.name: p.unit for p in robot.PARAMS},
              "channels_kPa": {k: [v[0] / 1e3, v[1] / 1e3] for k, v in dsg.channels.items()}, "parts": {}}
    meshes = []
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for part in dsg.parts:
        path = out / f"{name}_{part.name}.stl"
        tri = export_part(part, path, units=units, resolution=resolution)
        chk = surface_check(tri)
        lo, hi = np.minimum(lo, chk["lo"]), np.maximum(hi, chk["hi"])
        entry = {"file": path.name, "material": part.material, "triangles": chk["triangles"],
                 "watertight": chk["watertight"], "shells": chk["shells"], "volume_mm3": chk["volume"] / mm**3,
                 "bbox_mm": ((chk["hi"] - chk["lo"]) / mm).round(2).tolist()}
        if check and part.networks:
            entry["networks"] = chamber_check(part)
        report["parts"][part.name] = entry
        meshes.append((tri, part.material))
    report["bbox_mm"] = ((hi - lo) / mm).round(2).tolist()
    if dsg.size is not None:
        report["seed_size_mm"] = [s / mm for s in dsg.size]
    report["twins"] = [{"name": t.name, "length_mm": t.length / mm, "material": t.material,
                        "chambers": [{"name": c.name, "area_mm2": c.area / mm**2,
                                      "offset_mm": [o / mm for o in c.offset], "channel": c.channel}
                                     for c in t.chambers],
                        "base": np.asarray(t.base).round(6).tolist()} for t in dsg.twins]
    with atomic_path(out / f"{name}_board.toml") as tmp:
        tmp.write_text(board_profile(dsg))
    report["board_profile"] = f"{name}_board.toml"
    if preview:
        preview_png(meshes, out / f"{name}.png", title=robot.title)
        report["preview"] = f"{name}.png"
    write_json(out / f"{name}.json", report)
    return report


