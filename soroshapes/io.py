r"""Beam model files: a reduced beam written by one program (``soro trade --tol``) and loaded by another.

One JSON file per model (UTF-8, written atomically), readable with the standard library alone. Format
``soro-beam`` version 1; every length in m, every modulus in Pa, density in kg/m^3:

``format``, ``version``
    ``"soro-beam"``, 1.
``length`` [m], ``dofs`` (6 ints: torsion, bending_y, bending_z, stretch, shear_y, shear_z), ``segments``,
``base`` (4 x 4 pose of the clamped end [m]), ``damping`` (the beam's damping time constant [s])
    What :class:`~soroshapes.shapes.Shapes` takes.
``bases``
    6 entries, null for a fixed strain, else the basis of that strain: ``{"family": "chebyshev" | "legendre" |
    "pcc", "n": k, "orthonormal_length": L or null}`` (rebuilt exactly by the same constructor) or
    ``{"family": "data", "s": [...], "values": [[...]]}``: a data-driven (DVS) basis as its values at its spline
    knots ``s`` (normalized arc length), rebuilt by :meth:`~soroshapes.basis.Basis.from_data` (a linear
    combination of natural cubic splines on the same knots is one, so an orthonormalized data basis is stored
    exactly).
``section``
    ``{"kind": "rectangle", "width": w, "height": h}`` or ``{"kind": "circle", "radius": r}`` [m].
``material``
    ``{"E": Pa, "G": Pa, "density": kg/m^3, "damping": ratio}``: the small-strain moduli the beam uses.
``actuators``
    Input name -> polynomial coefficients ``c`` (degree x n) of the generalized force
    :math:`\tau(u) = \sum_{d \ge 1} c_d u^d` (:class:`soroshapes.dvs.PolynomialForce`; u in the input's unit).
``volumes``
    Cavity name -> ``{"c0": m^3, "c1": [n], "C2": [[n x n]]}``: :math:`V(q) = c_0 + c_1^T q + q^T C_2 q`.
``meta``
    Free provenance (what chose the model, its measured errors, the scene); not read back into the model.

:func:`save_beam` refuses a basis it cannot rebuild exactly (it checks the rebuilt values); :func:`load_beam`
returns the :class:`~soroshapes.shapes.Shapes` with its actuators attached and a :class:`BeamFile` with the rest.
"""
from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sorofem.errors import DataError, ParameterError

__all__ = ["FORMAT", "VERSION", "BeamFile", "Moduli", "basis_spec", "basis_from_spec", "save_beam", "load_beam"]

FORMAT, VERSION = "soro-beam", 1


@dataclass(frozen=True)
class Moduli:
    """The small-strain constants a beam reads from a material: ``E``, ``G`` [Pa], ``density`` [kg/m^3],
    ``damping`` (ratio)."""

    E: float
    G: float
    density: float
    damping: float = 0.0


@dataclass
class BeamFile:
    """What a model file holds besides the beam: actuator coefficients, cavity volume models, provenance."""

    actuators: dict
    volumes: dict = field(default_factory=dict)
    meta: dict = field(default_factory=dict)

    def volume(self, name, q):
        """Volume of cavity ``name`` [m^3] at coordinates ``q`` (the identified quadratic model)."""
        if name not in self.volumes:
            raise ParameterError(f"no volume model for cavity {name!r}; the file has {sorted(self.volumes)}")
        v = self.volumes[name]
        q = np.asarray(q, dtype=float)
        return float(v["c0"] + np.asarray(v["c1"]) @ q + q @ np.asarray(v["C2"]) @ q)


_NAMED = re.compile(r"^(chebyshev|legendre|pcc)\((\d+)\)$")
_ORTHO = re.compile(r"^orthonormal\((.*), L=([^)]*)\)$")


def basis_spec(basis, length):
    """The file entry of ``basis`` (a :class:`~soroshapes.basis.Basis` of a beam of ``length`` [m]); a
    ParameterError for a family the format cannot rebuild exactly."""
    name, ortho = basis.name, None
    m = _ORTHO.match(name)
    if m:
        name, ortho = m.group(1), float(length)
        if f"{ortho:g}" != m.group(2):
            raise ParameterError(f"basis {basis.name} was orthonormalized on another length than the beam's "
                                 f"{length:g} m; orthonormalize it with the beam's length")
    m = _NAMED.match(name)
    if m:
        spec = {"family": m.group(1), "n": int(m.group(2)), "orthonormal_length": ortho}
    elif name.startswith("data("):
        s = np.asarray(basis.breaks, dtype=float)
        spec = {"family": "data", "s": s.tolist(), "values": basis(s).tolist()}
    else:
        raise ParameterError(f"a model file stores chebyshev, legendre, pcc or data bases, not {basis.name}")
    # the rebuilt basis must be this one (between the knots too)
    br = np.asarray(basis.breaks, dtype=float)
    probe = np.unique(np.concatenate([np.linspace(0, 1, 97), 0.5 * (br[1:] + br[:-1])]))
    a, b = basis(probe), basis_from_spec(spec)(probe)
    if not np.allclose(a, b, rtol=1e-9, atol=1e-9 * max(1.0, float(np.abs(a).max()))):
        raise ParameterError(f"basis {basis.name} is not rebuilt exactly from its file entry (max difference "
                             f"{float(np.abs(a - b).max()):.3g}); this is a bug of soroshapes.io")
    return spec


def basis_from_spec(spec):
    """The :class:`~soroshapes.basis.Basis` of a file entry (:func:`basis_spec`)."""
    from .basis import Basis

    fam = spec.get("family")
    if fam == "data":
        return Basis.from_data(np.asarray(spec["s"], dtype=float), np.asarray(spec["values"], dtype=float))
    if fam not in ("chebyshev", "legendre", "pcc"):
        raise DataError(f"unknown basis family {fam!r} in a model file (known: chebyshev, legendre, pcc, data)")
    b = getattr(Basis, fam)(int(spec["n"]))
    L = spec.get("orthonormal_length")
    return b.orthonormalize(float(L)) if L is not None else b


def _section_spec(section):
    from sorofem.sdf.properties import section_properties

    props = section_properties(section)
    lo, hi = (np.asarray(v, dtype=float) for v in section.bounds)
    w, h = hi - lo
    if abs(props.area - w * h) <= 1e-6 * w * h:
        return {"kind": "rectangle", "width": float(w), "height": float(h)}
    r = 0.5 * w
    if abs(w - h) <= 1e-9 * w and abs(props.area - np.pi * r * r) <= 1e-3 * props.area:
        return {"kind": "circle", "radius": float(r)}
    raise ParameterError("a model file stores rectangular or circular sections; this section is neither")


def _section_from_spec(spec):
    from sorofem import sdf

    if spec["kind"] == "rectangle":
        return sdf.Rectangle(float(spec["width"]), float(spec["height"]))
    if spec["kind"] == "circle":
        return sdf.Circle(float(spec["radius"]))
    raise DataError(f"unknown section kind {spec['kind']!r} in a model file (rectangle or circle)")


def save_beam(path, shapes, actuators, volumes=None, meta=None):
    """Write a beam model file (format in the module docstring) atomically; returns the path.

    Parameters
    ----------
    path : path of the ``.json`` file.
    shapes : :class:`~soroshapes.shapes.Shapes` (its bases, dofs, length, section, moduli, base pose).
    actuators : dict
        Input name -> coefficients (degree, n) of :math:`\\tau(u)`, e.g. ``Identified.coefficients``.
    volumes : dict, optional
        Cavity name -> ``(c0, c1, C2)`` as ``Identified.volume_models`` [m^3].
    meta : dict, optional
        JSON-serializable provenance.
    """
    from sorofem.io import atomic_path

    bases = [None if shapes.dofs[i] == 0 else basis_spec(shapes.bases[i], shapes.length) for i in range(6)]
    doc = {
        "format": FORMAT, "version": VERSION, "length": shapes.length, "dofs": list(shapes.dofs),
        "segments": int(shapes.segments), "base": np.asarray(shapes.base, dtype=float).tolist(),
        "damping": float(shapes.damping), "bases": bases, "section": _section_spec(shapes.section),
        "material": {"E": shapes.E, "G": shapes.G, "density": shapes.density,
                     "damping": float(getattr(shapes.material, "damping", 0.0) or 0.0)},
        "actuators": {k: np.asarray(c, dtype=float).reshape(-1, shapes.n).tolist() for k, c in actuators.items()},
        "volumes": {k: {"c0": float(c0), "c1": np.asarray(c1, float).tolist(), "C2": np.asarray(C2, float).tolist()}
                    for k, (c0, c1, C2) in (volumes or {}).items()},
        "meta": meta or {},
    }
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        Path(tmp).write_text(json.dumps(doc, indent=1, default=float) + "\n")
    return path


def load_beam(path):
    """Read a beam model file: returns ``(shapes, beamfile)``, the :class:`~soroshapes.shapes.Shapes` with its
    actuators attached (in the file's order) and the :class:`BeamFile`."""
    from .dvs import PolynomialForce
    from .shapes import Shapes

    try:
        doc = json.loads(Path(path).read_text())
    except (OSError, ValueError) as e:
        raise DataError(f"cannot read the beam model file {path}: {e}") from e
    if doc.get("format") != FORMAT or doc.get("version") != VERSION:
        raise DataError(f"{path} is not a {FORMAT} version {VERSION} file (format {doc.get('format')!r}, "
                        f"version {doc.get('version')!r})")
    m = doc["material"]
    shp = Shapes([None if b is None else basis_from_spec(b) for b in doc["bases"]], tuple(doc["dofs"]),
                 length=float(doc["length"]), section=_section_from_spec(doc["section"]),
                 material=Moduli(m["E"], m["G"], m["density"], m.get("damping", 0.0)),
                 base=np.asarray(doc["base"], dtype=float), segments=int(doc["segments"]), damping=float(doc["damping"]))
    for name, c in doc["actuators"].items():
        shp.add_actuator(PolynomialForce(np.asarray(c, dtype=float)), name=name)
    return shp, BeamFile(doc["actuators"], doc.get("volumes", {}), doc.get("meta", {}))
