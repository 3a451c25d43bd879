r"""An SDF tree as data: a post-order program of op-codes and a constant vector, for one compiled interpreter.

:func:`to_program` walks a tree (its public contract: ``op``, ``params``, ``children``) and emits a stack
program that evaluates the signed distance *and its analytic gradient* at a point. Unlike the fused kernels
of :mod:`sorofem.sdf._codegen` (one generated kernel per tree structure), every tree becomes the same two
arrays, so a kernel that takes a program (``soroshapes._sdfeval``) is compiled once and serves every shape:
a network of beams touching a grooved wall or a bolt head runs without recompiling per shape.

Program
-------
``ops`` (K, 3) int64, one instruction per row ``(code, offset into consts, count)``; ``consts`` (float64). The
interpreter keeps a stack of points (3D; a 2D shape's points have z = 0) with, per level, the matrix
:math:`A` and factor :math:`s` that carry a child's gradient and distance back to its parent
(:math:`\nabla_x = A\,\nabla_y`, :math:`d_x = s\,d_y`), and a stack of (distance, gradient) values:

* primitives push the (distance, gradient) of the current point;
* ``PUSH_*`` transforms push the child's point (and A, s); ``POP`` applies A, s to the top value and drops the
  point; ``POP_EXTRUDE`` combines a 2D profile's value with the parent point's height;
* booleans replace the two top values by their combination; ``OFFSET``/``SHELL`` change the top value.

The equations and the tie rules (which operand's gradient a union takes where two distances are equal, the
gradient at a circle's centre) are those of the numpy path (:meth:`SDF._grad <sorofem.sdf.SDF.gradient>`);
the tests compare both to 1e-12. Nodes without an analytic gradient here (ellipse, cone, torus, rounded
rectangle, polyline, segment, strut, repeat, circular repeat, user subclasses) raise
:class:`NotImplementedError` naming the node.
"""
import numpy as np

__all__ = ["Program", "to_program", "OPCODES"]

#: op-codes of the program
(SPHERE, BOX, CYLINDER, PLANE, CAPSULE, POLYGON,
 UNION, INTERSECTION, DIFFERENCE, SMOOTH_UNION, SMOOTH_INTERSECTION, SMOOTH_DIFFERENCE, OFFSET, SHELL,
 PUSH_TRANSLATE, PUSH_LINEAR, PUSH_SCALE, PUSH_EXTRUDE, PUSH_REVOLVE, POP, POP_EXTRUDE) = range(21)

OPCODES = dict(sphere=SPHERE, box=BOX, cylinder=CYLINDER, plane=PLANE, capsule=CAPSULE, polygon=POLYGON,
               union=UNION, intersection=INTERSECTION, difference=DIFFERENCE, smooth_union=SMOOTH_UNION,
               smooth_intersection=SMOOTH_INTERSECTION, smooth_difference=SMOOTH_DIFFERENCE, offset=OFFSET,
               shell=SHELL, push_translate=PUSH_TRANSLATE, push_linear=PUSH_LINEAR, push_scale=PUSH_SCALE,
               push_extrude=PUSH_EXTRUDE, push_revolve=PUSH_REVOLVE, pop=POP, pop_extrude=POP_EXTRUDE)

#: half extent standing in for the missing z of a 2D box (never the largest of its q_i)
_FLAT = 1e300


class Program:
    """A lowered SDF tree: ``ops`` (K, 3) int64, ``consts`` (C,) float64, the stack depths ``values`` and
    ``points`` the interpreter needs, and the tree's ``dim``."""

    def __init__(self, ops, consts, values, points, dim):
        self.ops, self.consts, self.values, self.points, self.dim = ops, consts, values, points, dim

    def __repr__(self):
        return f"Program({len(self.ops)} ops, {len(self.consts)} constants, dim={self.dim})"


class _Emitter:
    def __init__(self):
        self.ops, self.consts = [], []
        self.depth = self.max_depth = 0
        self.level = self.max_level = 1

    def emit(self, code, values=(), count=0, push=0):
        self.ops.append((code, len(self.consts), int(count)))
        self.consts.extend(float(v) for v in np.ravel(values))
        self.depth += push
        self.max_depth = max(self.max_depth, self.depth)

    def enter(self, code, values=()):
        self.emit(code, values)
        self.level += 1
        self.max_level = max(self.max_level, self.level)

    def leave(self, code=POP, values=()):
        self.emit(code, values)
        self.level -= 1


def _pad(v, fill=0.0):
    out = np.full(3, fill)
    v = np.ravel(v)
    out[:len(v)] = v
    return out


def _pad_matrix(A):
    out = np.eye(3)
    d = A.shape[0]
    out[:d, :d] = A
    return out


def _lower(node, g):
    op, p, kids = node.op, node.params, node.children
    if op in ("sphere", "circle"):
        g.emit(SPHERE, [*_pad(p["center"]), p["radius"]], push=1)
    elif op == "box":
        g.emit(BOX, [*p["center"], *(np.asarray(p["size"]) / 2)], push=1)
    elif op == "rectangle":
        g.emit(BOX, [*_pad(p["center"]), p["width"] / 2, p["height"] / 2, _FLAT], push=1)
    elif op == "cylinder":
        g.emit(CYLINDER, [*p["center"], *p["axis"], p["radius"], p["height"] / 2], push=1)
    elif op in ("plane", "line"):
        g.emit(PLANE, [*_pad(p["point"]), *_pad(p["normal"])], push=1)
    elif op == "capsule":
        g.emit(CAPSULE, [*p["start"], *p["end"], p["radius"]], push=1)
    elif op == "polygon":
        v = np.asarray(p["vertices"], dtype=float)
        g.emit(POLYGON, v.reshape(-1), count=len(v), push=1)
    elif op in ("union", "intersection"):
        _lower(kids[0], g)
        for k in kids[1:]:
            _lower(k, g)
            g.emit(UNION if op == "union" else INTERSECTION, push=-1)
    elif op == "difference":
        _lower(kids[0], g)
        _lower(kids[1], g)
        g.emit(DIFFERENCE, push=-1)
    elif op in ("smooth_union", "smooth_intersection", "smooth_difference"):
        _lower(kids[0], g)
        _lower(kids[1], g)
        g.emit(OPCODES[op], [p["radius"]], push=-1)
    elif op == "offset":
        _lower(kids[0], g)
        g.emit(OFFSET, [p["distance"]])
    elif op == "shell":
        t = p["thickness"]
        _lower(kids[0], g)
        g.emit(SHELL, [{"inner": t / 2, "outer": -t / 2, "center": 0.0}[p["side"]], t / 2])
    elif op == "translate":
        g.enter(PUSH_TRANSLATE, _pad(p["offset"]))
        _lower(kids[0], g)
        g.leave()
    elif op in ("rotate", "mirror"):
        if op == "rotate":
            A = _pad_matrix(np.asarray(p["matrix"], dtype=float))
            shift = np.zeros(3)
        else:
            n = np.asarray(p["normal"], dtype=float)
            c = np.asarray(p["point"], dtype=float)
            H = np.eye(len(n)) - 2 * np.outer(n, n)
            A = _pad_matrix(H)
            shift = _pad(2 * np.dot(c, n) * n)
        # child point y_j = sum_i x_i A_ij + shift_j, gradient back: A grad_y
        g.enter(PUSH_LINEAR, [*A.reshape(-1), *shift])
        _lower(kids[0], g)
        g.leave()
    elif op == "scale":
        g.enter(PUSH_SCALE, [p["factor"]])
        _lower(kids[0], g)
        g.leave()
    elif op == "extrude":
        g.enter(PUSH_EXTRUDE)
        _lower(kids[0], g)
        g.leave(POP_EXTRUDE, [p["height"] / 2])
    elif op == "revolve":
        g.enter(PUSH_REVOLVE, [*p["axis"], p["offset"]])
        _lower(kids[0], g)
        g.leave()
    else:
        raise NotImplementedError(f"the SDF node {op!r} (no program form; its shape runs on the numpy path)")


def to_program(shape):
    """Lower ``shape`` (a 2D or 3D :class:`~sorofem.sdf.SDF`) to a :class:`Program`, or raise
    ``NotImplementedError`` naming the first node without a program form."""
    g = _Emitter()
    _lower(shape, g)
    ops = np.array(g.ops, dtype=np.int64).reshape(-1, 3)
    consts = np.array(g.consts, dtype=float)
    return Program(ops, consts, g.max_depth, g.max_level, shape.dim)
