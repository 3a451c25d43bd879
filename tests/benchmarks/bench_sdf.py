"""Point evaluations per second of a 10-primitive SDF tree on 10^6 points, one core.

Target (issue): >= 10 million points/s single core. Measured: the fused numba kernel (one generated loop
over points, all nodes inlined) against our plain numpy evaluation (node by node on the whole array) and the
chunked numpy path (node by node on cache-sized chunks), best of a few warm runs, in the same process.
"""
import os

os.environ.setdefault("NUMBA_NUM_THREADS", "1")  # single core (the kernel is serial anyway)

import time  # noqa: E402

import numpy as np  # noqa: E402

from sorofem import sdf  # noqa: E402
from sorofem.units import mm  # noqa: E402

N = 1_000_000


def ten_primitive_tree():
    """A gripper-finger-like solid: 10 primitives, booleans, rotations, translations, one smooth union."""
    body = sdf.Box([60 * mm, 15 * mm, 12 * mm])
    tip = sdf.Sphere(7.5 * mm, (30 * mm, 0, 0))
    base = sdf.Cylinder(8 * mm, 4 * mm, (-30 * mm, 0, 0), axis=(1, 0, 0))
    chambers = sdf.Union(*[sdf.Box([6 * mm, 11 * mm, 8 * mm], (x * mm, 0, 1 * mm)) for x in (-18, -6, 6, 18)])
    channel = sdf.Capsule((-35 * mm, 0, 1 * mm), (25 * mm, 0, 1 * mm), 1.5 * mm)
    pad = sdf.Torus(5 * mm, 1.5 * mm, (30 * mm, 0, -5 * mm))
    floor = sdf.Plane((0, 0, -7 * mm), (0, 0, -1))
    shape = ((body | tip).smooth_union(base, 2 * mm) - chambers - channel | pad) & floor
    return shape.rotate(15, axis=(0, 1, 0), deg=True).translate((0, 0, 5 * mm))


def _count_primitives(s):
    return 1 if not s.children else sum(_count_primitives(c) for c in s.children)


def _best(fn, repeat):
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def test_bench_sdf_points_per_second(record):
    shape = ten_primitive_tree()
    assert _count_primitives(shape) == 10
    rng = np.random.default_rng(0)
    lo, hi = shape.bounds
    p = rng.uniform(lo - 5 * mm, hi + 5 * mm, (N, 3))

    t0 = time.perf_counter()
    kernel = shape.compiled()
    kernel(p[:10])
    compile_s = time.perf_counter() - t0

    t_fused, d_fused = _best(lambda: shape(p, compiled=True), 5)
    t_numpy, d_numpy = _best(lambda: shape._eval(p), 3)           # plain numpy, node by node
    t_chunk, d_chunk = _best(lambda: shape(p, compiled=False), 3)  # numpy on 32k-point chunks

    assert np.allclose(d_fused, d_numpy, atol=1e-15, rtol=0)
    assert np.array_equal(d_chunk, d_numpy)
    assert np.mean(d_fused < 0) > 0.01  # the points do sample the solid

    figures = {
        "points": N,
        "primitives": 10,
        "fused_Mpts_per_s": round(N / t_fused / 1e6, 2),
        "numpy_Mpts_per_s": round(N / t_numpy / 1e6, 2),
        "numpy_chunked_Mpts_per_s": round(N / t_chunk / 1e6, 2),
        "speedup_fused_vs_numpy": round(t_numpy / t_fused, 2),
        "target_Mpts_per_s": 10.0,
        "compile_s": round(compile_s, 3),
    }
    record(**figures)
