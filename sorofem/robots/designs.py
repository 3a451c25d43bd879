r"""The four open-hardware robots of the seed (Sec. IV, Fig. 1) as parametric SDF designs.

Two kinds of soft block, both with exactly one inlet per network: a bore of the tube's outer diameter
``tube_od`` and depth ``port_depth`` for a push-in tube or a barbed fitting, in a solid mount block; the chambers
are closed otherwise (:func:`sorofem.robots.chamber_check` verifies it on a voxel grid).

- A *box bellows chain* ((a), the hand's and the gripper's fingers) along its local :math:`x` axis: ``n`` hollow
  rounded boxes (the bellows, length ``pitch - gap`` each, wall ``wall``) on a pitch ``pitch``, joined by a
  bridge around a square feed channel (side ``channel``) that runs through every chamber and back into the
  mount block, where it ends in the port.
- A *round bellows chain* ((b), (d)): a tube of outer diameter ``diameter`` with ``n_bellows`` circular-arc
  grooves (tori, ``depth`` deep) and a cavity that follows them at the distance ``wall``: the wall is equally
  thick everywhere and folds at the grooves, so that the chain stretches about ten times more per kPa than
  a box bellows chain of the same length (axisymmetric FEM, :func:`soro.robots.chain_stretch`); its bore
  runs from the mount block, where a feed channel (diameter ``channel``) joins it to the port, to the tip.
  Walls down to 1.0 mm: thinner Elastic 80A walls tear when the print is peeled off and leak.

(a) ``bending_actuator``: a bellows chain on an inextensible base layer (strain limiter), Elastic 80A,
    -10..100 kPa. Inflation lengthens the bellows side: the actuator bends towards the base layer.
(b) ``planar_actuator``: two round bellows chains side by side between a common mount block and a tip plate,
    two networks (left, right), -10..50 kPa: together they elongate, one at a time they bend in the plane;
    the seed states a ~100 x 100 mm planar workspace (``Design.workspace``), which the chains' stretch and
    their ``separation`` set.
(c) ``hand``: a PLA palm (pockets, M3 holes, tube passages) and five separate Elastic 80A fingers (bending
    actuators, 90 mm; thumb 80 mm, rolled to close towards the fingers), -10..60 kPa per finger;
    overall about 190 x 100 x 40 mm.
(d) ``manipulator``: three round bellows chains at 120 degrees about a hollow central axis (bores through both
    plates for tubes and cables) between a base plate and a top plate, -10..30 kPa; and a three-finger
    gripper (hub with one inlet and a manifold, fingers of box bellows around a 40 mm object), -30..60 kPa,
    that bolts to the top plate; the gripper's tube runs through the hollow axis. The seed states a
    ~150 x 150 x 150 mm workspace (``Design.workspace``).

Coordinates are in metres (SI); x is the length direction of (a)-(c), z the axis of (d).
"""
from __future__ import annotations

import math

import numpy as np

from .. import sdf
from ..errors import GeometryError
from ..units import kPa, mm
from ._core import Chamber, Design, Network, Param, Part, Robot, Twin

__all__ = ["BendingActuator", "PlanarActuator", "Hand", "Manipulator", "ROBOTS", "chain_meridian"]

_X, _Y, _Z = np.eye(3)
M3_CLEARANCE = 3.4 * mm      # hole diameter for an M3 screw
FIT = 0.2 * mm               # clearance of a part in a pocket (per side)
GRIPPER_WALL = 2.0 * mm      # wall and gap of the manipulator's gripper fingers (box bellows)
GRIPPER_GAP = 3.0 * mm


def _rbox(size, center, r):
    """Box of ``size`` [m] centred at ``center`` with edges rounded by ``r`` (exact offset of a smaller box)."""
    size = np.asarray(size, float)
    r = min(float(r), 0.45 * float(size.min()))
    return sdf.Box(size - 2 * r, center).offset(r) if r > 0 else sdf.Box(size, center)


def _common(**over):
    """Parameters shared by every bellows chain (defaults overridable per robot)."""
    base = dict(
        wall=Param("wall", 2.0 * mm, 1.5 * mm, 4.0 * mm, "mm", "wall thickness of the bellows; >= 1.5 mm holds "
                   "pressure in an elastomer resin"),
        gap=Param("gap", 3.0 * mm, 1.5 * mm, 8.0 * mm, "mm", "gap between neighbouring bellows"),
        channel=Param("channel", 2.0 * mm, 1.2 * mm, 4.0 * mm, "mm", "side of the square feed channel"),
        tube_od=Param("tube_od", 4.0 * mm, 2.0 * mm, 6.0 * mm, "mm", "outer diameter of the tube (port bore)"),
        port_depth=Param("port_depth", 6.0 * mm, 3.0 * mm, 12.0 * mm, "mm", "depth of the port bore"),
        block=Param("block", 12.0 * mm, 8.0 * mm, 30.0 * mm, "mm", "length of the solid mount block"),
        fillet=Param("fillet", 1.5 * mm, 0.0, 4.0 * mm, "mm", "edge rounding of the bellows"),
    )
    base.update(over)
    return base


class _Chain:
    """A bellows chain in local coordinates: bellows x in [gap, n pitch], y centred, z in [z0, z0 + height];
    the feed channel at height ``zc`` starts at x = ``x_in`` (inside the mount block). The bellows' solid
    reaches ``ext`` further down (into a base layer: parts must overlap, not touch, to fuse)."""

    def __init__(self, p, n, pitch, width, height, z0=0.0, zc=None, x_in=0.0, ext=0.0):
        w, ch, gap = p["wall"], p["channel"], p["gap"]
        tb = pitch - gap
        if tb < 2 * w + ch:
            raise GeometryError(f"bellows of length {tb / mm:g} mm (pitch - gap) cannot hold two walls of "
                                f"{w / mm:g} mm and the channel: increase 'pitch' or reduce 'gap'/'wall'")
        if min(width, height) < 2 * w + ch + 2 * mm:
            raise GeometryError(f"bellows of {width / mm:g} x {height / mm:g} mm leave no chamber inside walls of "
                                f"{w / mm:g} mm: increase 'width'/'height' or reduce 'wall'")
        self.n, self.pitch, self.width, self.height, self.z0, self.ext = n, pitch, width, height, z0, ext
        self.zc = z0 + w + ch / 2 if zc is None else zc
        self.length = n * pitch
        cx = gap + tb / 2
        outer = _rbox((tb, width, height + ext), (cx, 0, z0 + (height - ext) / 2), p["fillet"])
        inner = sdf.Box((tb - 2 * w, width - 2 * w, height - 2 * w), (cx, 0, z0 + height / 2))
        # explicit unions (not sdf.repeat): with fillet = 0 the tree is plain boxes and booleans, which
        # Mesh.from_sdf rebuilds exactly in OpenCASCADE (the FEM twin's mesh)
        def rep_union(s):
            return s.union(*[s.translate((k * pitch, 0, 0)) for k in range(1, n)]) if n > 1 else s
        bz = (max(z0, self.zc - ch / 2 - w), self.zc + ch / 2 + w)
        bridge = sdf.Box((self.length + 1 * mm, ch + 2 * w, bz[1] - bz[0]),
                         (self.length / 2 - 0.5 * mm, 0, (bz[0] + bz[1]) / 2))
        x_end = self.length - w - 0.3 * mm
        self.solid = rep_union(outer) | bridge
        self.void = rep_union(inner) | sdf.Box((x_end - x_in, ch, ch), ((x_end + x_in) / 2, 0, self.zc))
        #: a point inside each chamber [m] (local)
        self.chambers = np.array([[cx + k * pitch, 0, z0 + height / 2] for k in range(n)])
        self.inner = (width - 2 * w, height - 2 * w)

    def section(self, p):
        """The chain's 2D cross-section through a bellows, in local (y, z) [m], and its chamber."""
        w = p["wall"]
        hh = self.height + self.ext
        r = min(p["fillet"], 0.45 * min(self.width, hh))
        c = (0.0, self.z0 + (self.height - self.ext) / 2)
        outer = sdf.Rectangle(self.width - 2 * r, hh - 2 * r, c).offset(r) if r > 0 else \
            sdf.Rectangle(self.width, hh, c)
        cav = sdf.Rectangle(self.width - 2 * w, self.height - 2 * w, (0.0, self.z0 + self.height / 2))
        return outer, cav


def _round_params(**over):
    """Parameters of the round bellows chains of (b) and (d) (with :func:`_common`'s ports and blocks)."""
    base = _common(
        wall=Param("wall", 1.2 * mm, 1.0 * mm, 3.0 * mm, "mm", "wall thickness of the round bellows (equal "
                   "everywhere); >= 1.0 mm: thinner Elastic 80A walls tear when the print is peeled and leak"),
        diameter=Param("diameter", 36 * mm, 16 * mm, 60 * mm, "mm", "outer diameter of a bellows chain (its "
                       "crests)"),
        depth=Param("depth", 7 * mm, 2 * mm, 15 * mm, "mm", "depth of a groove (convolution): the crests' radius "
                    "minus the groove bottom's"),
        gap=Param("gap", 1.5 * mm, 1.0 * mm, 8.0 * mm, "mm", "width of a crest's chamber at its narrowest "
                  "(between the walls of neighbouring grooves)"),
        channel=Param("channel", 2.0 * mm, 1.2 * mm, 4.0 * mm, "mm", "diameter of the feed channel from the port "
                      "into the chain's bore"),
    )
    del base["fillet"]
    base.update(over)
    return base


class _RoundChain:
    r"""A round bellows chain along its local :math:`x` axis, x in [0, ``length``], centred on the x axis: a tube
    of outer radius :math:`R` = ``diameter``/2 and wall ``wall`` with ``n`` circular-arc grooves (the
    convolutions) on a pitch ``length``/``n``, groove k centred at x = (k + 1/2) pitch. A groove is a torus about
    the axis, tube radius :math:`b` = pitch/2 - ``wall`` - ``gap``/2, its bottom at :math:`R_r` = R - ``depth``;
    the cavity follows it at a distance ``wall`` (a torus of tube radius b + ``wall``), so the wall is ``wall``
    thick everywhere and the chamber inside each crest is ``gap`` wide at its narrowest. The cavity (the bore and
    every crest's chamber) is one closed volume from x = 0 to ``length``: the parts at both ends close it (the
    tube overlaps them by 0.5 mm: parts must overlap, not touch, to fuse). Built by cutting tori out of
    cylinders only (OpenCASCADE fails to fuse a torus with a coaxial cylinder): ``Mesh.from_sdf(...,
    method="csg")`` rebuilds it exactly (the FEM twin's mesh)."""

    def __init__(self, p, n, length):
        w, D, depth, gap = p["wall"], p["diameter"], p["depth"], p["gap"]
        pitch = length / n
        b = pitch / 2 - w - gap / 2
        R = D / 2
        Rr = R - depth
        if b < w:
            raise GeometryError(f"grooves of radius {b / mm:g} mm (pitch {pitch / mm:g} mm: 'length' / 'n_bellows', "
                                f"halved, less 'wall' and half the 'gap') are thinner than the wall: reduce "
                                "'n_bellows', 'gap' or 'wall', or increase 'length'")
        if 2 * b < depth + 1 * mm:
            raise GeometryError(f"grooves of radius {b / mm:g} mm cannot reach 'depth' {depth / mm:g} mm from the "
                                "crest with a mouth (their torus would be a sealed void in the wall): reduce "
                                "'depth', or widen the pitch ('length' / 'n_bellows'), or reduce 'gap'/'wall'")
        if Rr - w < max(p["channel"] / 2 + 1 * mm, 2 * mm):
            raise GeometryError(f"grooves down to a radius of {Rr / mm:g} mm ('diameter'/2 - 'depth') leave no bore "
                                f"inside walls of {w / mm:g} mm: reduce 'depth' or 'wall', or increase 'diameter'")
        self.n, self.pitch, self.length, self.R, self.Rr, self.b, self.w = n, pitch, length, R, Rr, b, w
        self.Rv = Rr + b
        xs = [(k + 0.5) * pitch for k in range(n)]
        self.xs = xs
        solid = sdf.Cylinder(R, length + 1 * mm, (length / 2, 0, 0), axis=_X)
        void = sdf.Cylinder(R - w, length, (length / 2, 0, 0), axis=_X)
        for x in xs:
            solid = solid - sdf.Torus(self.Rv, b, (x, 0, 0), axis=_X)
            void = void - sdf.Torus(self.Rv, b + w, (x, 0, 0), axis=_X)
        self.solid, self.void = solid, void
        #: a point inside each crest's chamber and one in the bore [m] (local)
        rc = R - w - min(0.5 * mm, (R - w - self.Rv) / 2)
        self.chambers = np.array([[k * pitch, 0.0, rc] for k in range(1, n)] + [[pitch / 2, 0.0, 0.0]])
        #: mean radius of the wall's mid-surface [m] (crest and groove bottom): pi Rm^2 is the chain's effective
        #: pressure area
        self.Rm = (R + Rr - w) / 2

    def feed(self, p, x0, x1):
        """The feed channel along x from ``x0`` to ``x1`` (local) [m]."""
        return sdf.Cylinder(p["channel"] / 2, x1 - x0, ((x0 + x1) / 2, 0, 0), axis=_X)

    def section(self):
        """The twin's 2D section of the chain, centred at (0, 0) in local (y, z): the slice through a crest (the
        ring of radii R - ``wall`` .. R; its modulus is the bellows' effective one), and the chamber: the disk of
        radius :attr:`Rm` (the effective pressure area of the bellows)."""
        return sdf.Circle(self.R) - sdf.Circle(self.R - self.w), sdf.Circle(self.Rm)

    def meridian(self, block=6 * mm, tip=4 * mm):
        r"""The chain's meridian section for an axisymmetric FEM: (r, x) = (x, y) in the half plane x >= 0, the
        chain along y in [0, ``length``] between a solid block y in [-``block``, 0] and a solid tip
        y in [``length``, ``length`` + ``tip``] of its radius. Returns (the wall region, the cavity) [m]."""
        L, R, w = self.length, self.R, self.w
        outer = sdf.Rectangle(R, L + block + tip, (R / 2, (L + tip - block) / 2))
        cav = sdf.Rectangle(R - w, L, ((R - w) / 2, L / 2))
        for y in self.xs:
            outer = outer - sdf.Circle(self.b, (self.Rv, y))
            cav = cav - sdf.Circle(self.b + w, (self.Rv, y))
        return outer - cav, cav


def _port(p, x0, y, z):
    """The port bore along +x from the block face x = x0 (a cylinder overshooting the face by 1 mm)."""
    d = p["port_depth"]
    return sdf.Cylinder(p["tube_od"] / 2, d + 1 * mm, (x0 + (d - 1 * mm) / 2, y, z), axis=_X)


def _finger(p, length, n, width, height, base, name, material="Elastic80A"):
    """A bending actuator in local coordinates: mount block x in [0, block], base layer z in [0, base],
    bellows above it; port on the block's back face (x = 0). Returns (solid, port, chambers, chain, twin
    section data)."""
    blk = p["block"]
    pitch = (length - blk) / n
    ch = _Chain(p, n, pitch, width, height - base, z0=base, x_in=p["port_depth"] - 0.5 * mm - blk, ext=base)
    if ch.zc - p["tube_od"] / 2 < p["wall"]:
        raise GeometryError(f"the port bore (tube_od {p['tube_od'] / mm:g} mm) would cut through the block's "
                            f"floor: reduce 'tube_od' or increase 'base'/'wall'")
    half_hole = M3_CLEARANCE / 2
    y_hole = width / 2 - p["wall"] - half_hole
    x_hole = blk / 2
    if y_hole - half_hole - p["wall"] < p["tube_od"] / 2:
        # no room beside the port bore: the holes go behind it, beside the feed channel
        x_hole = (p["port_depth"] + blk) / 2
        if (y_hole - half_hole - p["channel"] / 2 < 1.2 * mm or x_hole - half_hole < p["port_depth"] + 0.8 * mm
                or blk - x_hole - half_hole < 0.8 * mm):
            raise GeometryError(f"width {width / mm:g} mm and block {blk / mm:g} mm leave no room for the M3 "
                                "holes beside or behind the port: increase 'width' or 'block', or reduce "
                                "'tube_od'/'port_depth'")
    body = (sdf.Box((blk, width, height), (blk / 2, 0, height / 2))
            | sdf.Box((length - blk + 0.5 * mm, width, base), (blk + (length - blk - 0.5 * mm) / 2, 0, base / 2))
            | ch.solid.translate((blk, 0, 0)))
    holes = [sdf.Cylinder(half_hole, 2 * height, (x_hole, s * y_hole, height / 2)) for s in (-1, 1)]
    port = _port(p, 0.0, 0.0, ch.zc)
    solid = body - ch.void.translate((blk, 0, 0)) - port - holes[0] - holes[1]
    chambers = ch.chambers + [blk, 0, 0]
    # the twin's section: bellows with the base layer below, centred on its centroid
    outer, cav = ch.section(p)
    sec = outer | sdf.Rectangle(width, base, (0, base / 2))
    return dict(solid=solid, port=port, chambers=chambers, chain=ch, section=sec - cav, cavity=cav,
                length=length - blk, block=blk, holes=(x_hole, y_hole), name=name, material=material)


def _centred_twin(name, length, section, cavities, material, base_pose, channels):
    """A :class:`Twin` whose section is shifted to its centroid; chamber offsets relative to it."""
    from ..sdf import section_properties
    props = section_properties(section)
    c = np.asarray(props.centroid)
    chambers = []
    for (cav, ch_name) in zip(cavities, channels):
        cp = section_properties(cav)
        chambers.append(Chamber(ch_name, float(cp.area), tuple(np.asarray(cp.centroid) - c), ch_name))
    pose = np.array(base_pose, float)
    pose[:3, 3] = pose[:3, 3] + pose[:3, 1] * c[0] + pose[:3, 2] * c[1]
    return Twin(name, float(length), section.translate(-c), material, tuple(chambers), pose)


def _pose(R=np.eye(3), t=(0, 0, 0)):
    g = np.eye(4)
    g[:3, :3], g[:3, 3] = R, t
    return g


# --------------------------------------------------------------------------------------------------- (a)
class BendingActuator(Robot):
    name = "bending_actuator"
    title = "(a) soft bending actuator: bellows on an inextensible layer, Elastic 80A, -10..100 kPa"
    PRESSURE = (-10 * kPa, 100 * kPa)
    PARAMS = tuple(_common(
        length=Param("length", 100 * mm, 50 * mm, 200 * mm, "mm", "overall length, mount block included"),
        n_bellows=Param("n_bellows", 8, 3, 20, "count", "number of bellows"),
        width=Param("width", 20 * mm, 12 * mm, 40 * mm, "mm", "width of the bellows and base (y)"),
        height=Param("height", 20 * mm, 10 * mm, 40 * mm, "mm", "overall height, base layer included (z)"),
        base=Param("base", 2.0 * mm, 1.0 * mm, 6.0 * mm, "mm", "thickness of the inextensible base layer"),
    ).values())

    def build(self, p):
        f = _finger(p, p["length"], p["n_bellows"], p["width"], p["height"], p["base"], "actuator")
        net = Network("bend", f["port"], tuple(map(tuple, f["chambers"])), self.PRESSURE)
        part = Part("actuator", f["solid"], "Elastic80A", (net,), feature=min(p["wall"], p["channel"]))
        twin = _centred_twin("actuator", f["length"], f["section"], [f["cavity"]], "Elastic80A",
                             _pose(t=(f["block"], 0, 0)), ["bend"])
        return Design(self.name, p, (part,), {"bend": self.PRESSURE}, (twin,), None)


# --------------------------------------------------------------------------------------------------- (b)
class PlanarActuator(Robot):
    name = "planar_actuator"
    title = "(b) planar soft actuator: two round bellows networks in parallel, -10..50 kPa"
    PRESSURE = (-10 * kPa, 50 * kPa)
    PARAMS = tuple(_round_params(
        length=Param("length", 160 * mm, 60 * mm, 250 * mm, "mm", "overall length, block and tip plate included"),
        n_bellows=Param("n_bellows", 12, 3, 30, "count", "convolutions (grooves) per network"),
        separation=Param("separation", 82 * mm, 1 * mm, 120 * mm, "mm", "gap between the two chains' crests (their "
                         "distance sets how far one network bends the actuator against the other)"),
        tip=Param("tip", 4 * mm, 2 * mm, 10 * mm, "mm", "thickness of the tip plate"),
    ).values())

    def build(self, p):
        blk, tip, D = p["block"], p["tip"], p["diameter"]
        ch = _RoundChain(p, p["n_bellows"], p["length"] - blk - tip)
        R = D / 2
        yc = R + p["separation"] / 2
        total_w = 2 * D + p["separation"]
        if yc - p["tube_od"] / 2 - M3_CLEARANCE / 2 < p["wall"] + 1 * mm:
            raise GeometryError("no room for the M3 holes between the ports: increase 'separation' or 'diameter'")
        solid = (sdf.Box((blk, total_w, D), (blk / 2, 0, R))
                 | sdf.Box((tip, total_w, D), (blk + ch.length + tip / 2 - 0.01 * mm, 0, R)))
        nets, voids, names = [], [], []
        for s, name in ((1, "left"), (-1, "right")):
            at = (blk, s * yc, R)
            solid = solid | ch.solid.translate(at)
            voids.append((ch.void | ch.feed(p, p["port_depth"] - 0.5 * mm - blk, 0.5 * mm)).translate(at))
            port = _port(p, 0.0, s * yc, R)
            nets.append(Network(name, port, tuple(map(tuple, ch.chambers + at)), self.PRESSURE))
            names.append(name)
        hole = [sdf.Cylinder(M3_CLEARANCE / 2, 2 * D, (x, 0, R)) for x in (blk / 4, 3 * blk / 4)]
        for v in voids:
            solid = solid - v
        for n_ in nets:
            solid = solid - n_.port
        solid = solid - hole[0] - hole[1]
        part = Part("actuator", solid, "Elastic80A", tuple(nets), feature=min(p["wall"], p["channel"]))
        ring, cav = ch.section()
        sec = ring.translate((yc, 0.0)) | ring.translate((-yc, 0.0))
        cavs = [cav.translate((yc, 0.0)), cav.translate((-yc, 0.0))]
        twin = _centred_twin("actuator", ch.length, sec, cavs, "Elastic80A", _pose(t=(blk, 0, R)), names)
        return Design(self.name, p, (part,), {n: self.PRESSURE for n in names}, (twin,), None,
                      workspace=(100 * mm, 100 * mm))


# --------------------------------------------------------------------------------------------------- (c)
_FINGERS = ("index", "middle", "ring", "little")


class Hand(Robot):
    name = "hand"
    title = "(c) composable five-finger soft hand: Elastic 80A fingers on a PLA palm, -10..60 kPa per finger"
    PRESSURE = (-10 * kPa, 60 * kPa)
    PARAMS = tuple(_common(
        finger_length=Param("finger_length", 90 * mm, 60 * mm, 120 * mm, "mm", "length of a finger, block "
                            "included"),
        thumb_length=Param("thumb_length", 80 * mm, 50 * mm, 110 * mm, "mm", "length of the thumb"),
        n_bellows=Param("n_bellows", 8, 3, 16, "count", "bellows per finger (the thumb has one less)"),
        finger_width=Param("finger_width", 16 * mm, 12 * mm, 24 * mm, "mm", "width of a finger"),
        finger_height=Param("finger_height", 24 * mm, 14 * mm, 30 * mm, "mm", "height of a finger, base "
                            "included"),
        base=Param("base", 2.0 * mm, 1.0 * mm, 6.0 * mm, "mm", "thickness of a finger's base layer"),
        palm_length=Param("palm_length", 112 * mm, 80 * mm, 160 * mm, "mm", "length of the palm (x)"),
        palm_width=Param("palm_width", 100 * mm, 80 * mm, 140 * mm, "mm", "width of the palm (y)"),
        palm_thickness=Param("palm_thickness", 32 * mm, 20 * mm, 50 * mm, "mm", "thickness of the palm (z)"),
        pocket_floor=Param("pocket_floor", 16 * mm, 6 * mm, 40 * mm, "mm", "height of the finger pockets' floor"),
        finger_gap=Param("finger_gap", 2 * mm, 1 * mm, 10 * mm, "mm", "gap between neighbouring fingers"),
    ).values())

    def build(self, p):
        L, Wp, Tp = p["palm_length"], p["palm_width"], p["palm_thickness"]
        fw, fh, blk = p["finger_width"], p["finger_height"], p["block"]
        if p["pocket_floor"] + fh / 2 > Tp:
            raise GeometryError("the finger pockets would hold less than half a finger's block: increase "
                                "'palm_thickness' or lower 'pocket_floor'")
        need = 4 * fw + 4 * p["finger_gap"] + fh
        if need > Wp:
            raise GeometryError(f"four fingers and the thumb need {need / mm:g} mm across, the palm is "
                                f"{Wp / mm:g} mm wide: increase 'palm_width' or reduce 'finger_width'/'finger_gap'")
        x0 = L - blk
        mounts = []   # (name, length, n, rotation, translation)
        for k, name in enumerate(_FINGERS):
            y = -Wp / 2 + fw / 2 + k * (fw + p["finger_gap"])
            mounts.append((name, p["finger_length"], p["n_bellows"], np.eye(3), (x0, y, p["pocket_floor"])))
        # the thumb is rolled by -90 degrees about x: its base layer faces the fingers (-y), so it closes
        # sideways towards them; its block's mid-plane sits at the palm's top face
        Rt = np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]], float)
        yt = Wp / 2 - fh
        mounts.append(("thumb", p["thumb_length"], max(p["n_bellows"] - 1, 3), Rt, (x0, yt, Tp)))
        palm = _rbox((L, Wp, Tp), (L / 2, 0, Tp / 2), 2 * mm)
        parts, nets_twins, channels = [], [], {}
        for name, length, n, R, t in mounts:
            f = _finger(p, length, n, fw, fh, p["base"], name)
            place = (lambda s, R=R, t=t: s.rotate(matrix=R).translate(t))
            solid = place(f["solid"])
            port = place(f["port"])
            chambers = tuple(map(tuple, f["chambers"] @ R.T + t))
            net = Network(name, port, chambers, self.PRESSURE)
            parts.append(Part(name, solid, "Elastic80A", (net,), feature=min(p["wall"], p["channel"])))
            channels[name] = self.PRESSURE
            # the palm's pocket (block + fit, open upwards), the screw holes and the tube passage
            corners = np.array([[x, y, z] for x in (0, blk) for y in (-fw / 2, fw / 2) for z in (0, fh)]) @ R.T + t
            lo, hi = corners.min(axis=0) - FIT, corners.max(axis=0) + FIT
            hi[2] = max(hi[2], Tp + 1 * mm)
            palm = palm - sdf.Box(hi - lo, (lo + hi) / 2)
            xh, yh = f["holes"]
            # screws along the finger's z: through the palm's floor under a finger; for the thumb, through its
            # block into the palm's web beside it
            depth = 4 * Tp if name != "thumb" else fh + 8 * mm
            for s in (-1, 1):
                c = np.array([xh, s * yh, fh / 2 - (depth - fh) / 2 * (name == "thumb")]) @ R.T + t
                palm = palm - sdf.Cylinder(M3_CLEARANCE / 2, depth, c, axis=tuple(R @ _Z))
            pc = np.array([0.0, 0.0, f["chain"].zc]) @ R.T + t
            palm = palm - sdf.Cylinder(p["tube_od"] / 2 + 1 * mm, L, (x0 - L / 2 + 0.5 * mm, pc[1], pc[2]), axis=_X)
            nets_twins.append(_centred_twin(name, f["length"], f["section"], [f["cavity"]], "Elastic80A",
                                            _pose(R, np.asarray(t) + R @ [blk, 0, 0]), [name]))
        parts.insert(0, Part("palm", palm, "PLA", (), feature=2 * mm))
        return Design(self.name, p, tuple(parts), channels, tuple(nets_twins), (190 * mm, 100 * mm, 40 * mm))


# --------------------------------------------------------------------------------------------------- (d)
class Manipulator(Robot):
    name = "manipulator"
    title = "(d) manipulator of three round bellows networks with a hollow axis, -10..30 kPa, and a " \
            "three-finger gripper, -30..60 kPa"
    PRESSURE = (-10 * kPa, 30 * kPa)
    GRIPPER_PRESSURE = (-30 * kPa, 60 * kPa)
    PARAMS = tuple(_round_params(
        diameter=Param("diameter", 30 * mm, 16 * mm, 60 * mm, "mm", "outer diameter of a bellows chain (its "
                       "crests)"),
        length=Param("length", 120 * mm, 40 * mm, 250 * mm, "mm", "length of the bellows chains (z)"),
        n_bellows=Param("n_bellows", 10, 3, 30, "count", "convolutions per chain"),
        radius=Param("radius", 26 * mm, 12 * mm, 120 * mm, "mm", "distance of the chains from the axis"),
        hollow=Param("hollow", 14 * mm, 6 * mm, 30 * mm, "mm", "diameter of the hollow central axis"),
        plate=Param("plate", 10 * mm, 8 * mm, 20 * mm, "mm", "thickness of the base plate"),
        top=Param("top", 6 * mm, 4 * mm, 15 * mm, "mm", "thickness of the top plate"),
        object_diameter=Param("object_diameter", 40 * mm, 20 * mm, 80 * mm, "mm", "object the gripper holds"),
        gripper_length=Param("gripper_length", 50 * mm, 30 * mm, 90 * mm, "mm", "length of a gripper finger"),
        hub=Param("hub", 16 * mm, 12 * mm, 30 * mm, "mm", "thickness of the gripper hub"),
        # the gripper's fingers are bending actuators of box bellows (_Chain): they keep its parameters
        fillet=Param("fillet", 1.5 * mm, 0.0, 4.0 * mm, "mm", "edge rounding of the gripper's bellows"),
    ).values())

    def build(self, p):
        R0, Tb, Tt = p["radius"], p["plate"], p["top"]
        n, L = p["n_bellows"], p["length"]
        R = p["diameter"] / 2
        if R0 - R < p["hollow"] / 2 + p["wall"]:
            raise GeometryError("the chains would cut into the hollow axis: increase 'radius' or reduce "
                                "'diameter'/'hollow'")
        if R0 * math.sqrt(3) < 2 * R + 1 * mm:
            raise GeometryError("neighbouring chains would touch: increase 'radius' or reduce 'diameter'")
        ch = _RoundChain(p, n, L)
        Rp = R0 + R + 6 * mm
        r_hole = 15 * mm
        if math.sqrt(R0**2 + r_hole**2 - R0 * r_hole) < R + M3_CLEARANCE / 2 + p["wall"]:
            raise GeometryError("the top plate's M3 holes would cut into the chains: increase 'radius'")
        body = (sdf.Cylinder(Rp, Tb, (0, 0, Tb / 2)) | sdf.Cylinder(R0 + R + 1 * mm, Tt,
                                                                      (0, 0, Tb + L + Tt / 2 - 0.01 * mm)))
        voids, nets, names, cavs2d, sec2d = [], [], [], [], None
        ring, cav = ch.section()
        for k in range(3):
            phi = math.pi / 2 + 2 * math.pi * k / 3
            er = np.array([math.cos(phi), math.sin(phi), 0.0])
            Rk = np.column_stack([_Z, np.cross(er, _Z), er])   # local x -> z, local z -> radial
            t = np.array([R0 * er[0], R0 * er[1], Tb])
            body = body | ch.solid.rotate(matrix=Rk).translate(t)
            feed = ch.feed(p, p["port_depth"] - 0.5 * mm - Tb, 0.5 * mm)
            voids.append((ch.void | feed).rotate(matrix=Rk).translate(t))
            port = sdf.Cylinder(p["tube_od"] / 2, p["port_depth"] + 1 * mm,
                                (t[0], t[1], (p["port_depth"] - 1 * mm) / 2))
            name = f"bellows{k + 1}"
            nets.append(Network(name, port, tuple(map(tuple, ch.chambers @ Rk.T + t)), self.PRESSURE))
            names.append(name)
            # the twin's section in its body (y, z) = global (x, y)
            o = ring.translate(tuple(t[:2]))
            sec2d = o if sec2d is None else sec2d | o
            cavs2d.append(cav.translate(tuple(t[:2])))
        holes = []
        for k in range(3):
            a = math.pi / 6 + 2 * math.pi * k / 3
            holes.append(sdf.Cylinder(M3_CLEARANCE / 2, 2 * Tb, ((Rp - 4 * mm) * math.cos(a),
                                                                 (Rp - 4 * mm) * math.sin(a), Tb / 2)))
            holes.append(sdf.Cylinder(M3_CLEARANCE / 2, 4 * Tt, (r_hole * math.cos(a), r_hole * math.sin(a),
                                                                 Tb + L + Tt / 2)))
        axis = sdf.Cylinder(p["hollow"] / 2, 3 * (Tb + L + Tt), (0, 0, (Tb + L + Tt) / 2))
        solid = body - axis
        for v in voids + [n_.port for n_ in nets] + holes:
            solid = solid - v
        body_part = Part("manipulator", solid, "Elastic80A", tuple(nets), feature=min(p["wall"], p["channel"]))
        twin = _centred_twin("manipulator", L, sec2d, cavs2d, "Elastic80A",
                             _pose(np.column_stack([_Z, _X, _Y]), (0, 0, Tb)), names)
        gripper, gtwins = self._gripper(p, Tb + L + Tt)
        channels = {nm: self.PRESSURE for nm in names}
        channels["gripper"] = self.GRIPPER_PRESSURE
        return Design(self.name, p, (body_part, gripper), channels, (twin, *gtwins), None,
                      workspace=(150 * mm, 150 * mm, 150 * mm))

    def _gripper(self, p, z0):
        """The gripper: a hub z in [z0, z0 + hub] with the port at the bottom centre (under the hollow axis),
        three spokes to three fingers pointing +z, base layers facing the axis around the object."""
        Th, Lg = p["hub"], p["gripper_length"]
        rf = p["object_diameter"] / 2 + 2 * mm
        fw, fh, base = 14 * mm, 14 * mm, 2 * mm
        # the gripper's fingers are box bellows with the walls and gaps of (a) and the hand (2 and 3 mm): the
        # parameters 'wall' and 'gap' of (d) are its round bellows'
        q = dict(p, block=0.0, wall=GRIPPER_WALL, gap=GRIPPER_GAP)
        nb = max(3, int(Lg // (10 * mm)))        # bellows of the gripper's fingers: a pitch of about 10 mm
        pitch = Lg / nb
        ch = _Chain(q, nb, pitch, fw, fh - base, z0=base, x_in=-Th / 2 - p["channel"] / 2, ext=base)
        Rg = rf + fh + 3 * mm
        zm = z0 + Th / 2
        if p["port_depth"] + 0.5 * mm > Th / 2 - p["channel"] / 2:
            raise GeometryError("the gripper's port bore must end below the hub's mid-plane manifold (a plug "
                                "in the bore must not cut the spokes apart): increase 'hub' or reduce 'port_depth'")
        hub = sdf.Cylinder(Rg, Th, (0, 0, z0 + Th / 2))
        voids, chambers, twins = [], [], []
        finger_solids = []
        for k in range(3):
            phi = math.pi / 2 + 2 * math.pi * k / 3
            er = np.array([math.cos(phi), math.sin(phi), 0.0])
            Rk = np.column_stack([_Z, np.cross(er, _Z), er])   # local x -> z, local z -> radial (base inward)
            t = np.array([rf * er[0], rf * er[1], z0 + Th])
            layer = sdf.Box((Lg + 0.5 * mm, fw, base), ((Lg - 0.5 * mm) / 2, 0, base / 2))
            finger_solids.append((ch.solid | layer).rotate(matrix=Rk).translate(t))
            voids.append(ch.void.rotate(matrix=Rk).translate(t))
            rc = rf + ch.zc
            voids.append(sdf.Box((rc + p["channel"] / 2, p["channel"], p["channel"]),
                                 ((rc + p["channel"] / 2) / 2, 0, 0)).rotate(phi, axis=_Z).translate((0, 0, zm)))
            chambers.extend(map(tuple, ch.chambers @ Rk.T + t))
            outer, cav = ch.section(q)
            sec = outer | sdf.Rectangle(fw, base, (0, base / 2))
            twins.append(_centred_twin(f"gripper{k + 1}", Lg, sec - cav, [cav], "Elastic80A", _pose(Rk, t),
                                       ["gripper"]))
        port = sdf.Cylinder(p["tube_od"] / 2, p["port_depth"] + 1 * mm, (0, 0, z0 + (p["port_depth"] - 1 * mm) / 2))
        a = z0 + p["port_depth"] - 0.5 * mm
        voids.append(sdf.Box((p["channel"], p["channel"], zm - a), (0, 0, (a + zm) / 2)))   # bore -> manifold
        solid = hub.union(*finger_solids)
        for v in voids:
            solid = solid - v
        solid = solid - port
        for k in range(3):
            a = math.pi / 6 + 2 * math.pi * k / 3
            solid = solid - sdf.Cylinder(M3_CLEARANCE / 2, 4 * Th, (15 * mm * math.cos(a), 15 * mm * math.sin(a),
                                                                    z0 + Th / 2))
        net = Network("gripper", port, tuple(chambers), self.GRIPPER_PRESSURE)
        return Part("gripper", solid, "Elastic80A", (net,), feature=min(q["wall"], p["channel"])), twins


#: The robots by name.
ROBOTS = {r.name: r for r in (BendingActuator(), PlanarActuator(), Hand(), Manipulator())}

#: The robots built of round bellows chains, and the length [m] of their chains from the parameters.
_ROUND = {"planar_actuator": lambda p: p["length"] - p["block"] - p["tip"], "manipulator": lambda p: p["length"]}


def chain_meridian(name, **params):
    """The meridian section of one bellows chain of robot ``name`` ((b) or (d); parameters in SI) for an
    axisymmetric FEM: ``(wall, cavity, length)``, the chain along y in [0, length] [m] between a solid block
    (y < 0, clamp its bottom) and a solid tip, the cavity the region whose boundary carries the pressure."""
    if name not in _ROUND:
        raise GeometryError(f"{name!r} has no round bellows chain; these do: {sorted(_ROUND)}")
    robot = ROBOTS[name]
    p = robot.resolve(**params)
    L = _ROUND[name](p)
    wall, cav = _RoundChain(p, p["n_bellows"], L).meridian()
    return wall, cav, L
