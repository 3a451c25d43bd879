"""The speed-accuracy study of beam models against their FEM parent (``soro trade``).

For each basis family (DVS: the POD of the training snapshots, Chebyshev, PCC) and number of modes, a beam is
built, its actuation identified on the training snapshots (:func:`soroshapes.dvs.identify`) and compared with
FEM (:func:`soroshapes.dvs.compare`) on training and test snapshots: tip and shape errors [fractions of the
length] and the median time per static solve [s]. :func:`cheapest` is the one selection rule (the table's
marked row, the verdict, ``soro trade``'s exit status); :func:`trade_report` writes ``trade.txt`` and
``trade.png``.

This is application code (it draws figures and writes reports); the library parts it uses are in
:mod:`soroshapes.dvs`.
"""
import sys
from pathlib import Path

import numpy as np

from sorofem.errors import ParameterError
from soroshapes.dvs import compare, dvs_basis, identify, recover_strains

__all__ = ["trade", "cheapest", "within", "trade_table", "trade_text", "trade_figure", "trade_report",
           "trade_files", "run_trade", "SELECTION_KEYS", "TIME_BAND"]


def trade(train, test, make_shapes, inputs, modes=range(1, 7), strain=2, families=("dvs", "chebyshev", "pcc"),
          degree=3, contact=None, repeats=5):
    r"""The speed-accuracy trade of beam models of one FEM case.

    For each family (``"dvs"``: the POD of ``train``; ``"chebyshev"``; ``"pcc"``: piecewise constant on k
    equal sections) and each number of modes k, builds ``make_shapes(bases, dofs)`` with k modes on the strain
    ``strain`` (2 = bending about z, the planar bending), identifies its actuation on ``train``
    (:func:`soroshapes.dvs.identify`) and measures (:func:`soroshapes.dvs.compare`) the tip and shape errors on
    ``train`` and on ``test``
    (snapshots not used for training) and the time per static solve. With ``contact = (data, add)``, the
    DVS modes are learned from ``train`` and ``data`` together and each model, once identified, is also
    compared with ``data`` after ``add(shapes)`` gave it the obstacle (columns ``*_contact``). The time per
    solve (``solve_time_s``) is the median over ``repeats`` solves of every training and test snapshot.
    Returns a list of rows (dicts).
    """
    from soroshapes.basis import Basis

    rows = []
    for fam in families:
        for k in modes:
            dofs = [0] * 6
            dofs[strain] = k
            if fam == "dvs":
                bases, kept, _ = dvs_basis([train, contact[0]] if contact else train, dofs)
                if kept[strain] < k:
                    continue                   # the data hold fewer independent shapes than k
            elif fam == "chebyshev":
                bases = [Basis.chebyshev(k).orthonormalize(train.length) if i == strain else None
                         for i in range(6)]
            elif fam == "pcc":
                bases = [Basis.pcc(k) if i == strain else None for i in range(6)]
            else:
                raise ParameterError(f"unknown basis family {fam!r}: use dvs, chebyshev or pcc")
            shp = make_shapes(bases, tuple(dofs))
            identify(shp, train, inputs=inputs, degree=degree)
            tr, te = compare(shp, train, inputs, repeats), compare(shp, test, inputs, repeats)
            row = {"family": fam, "modes": k, "tip_error_train": float(tr["tip_error"].max()),
                   "shape_error_train": float(tr["shape_error"].max()),
                   "tip_error_test": float(te["tip_error"].max()),
                   "shape_error_test": float(te["shape_error"].max()),
                   "solve_time_s": float(np.median(np.concatenate([tr["solve_times"], te["solve_times"]])))}
            if contact:
                contact[1](shp)
                co = compare(shp, contact[0], inputs, repeats)
                row.update(tip_error_contact=float(co["tip_error"].max()),
                           shape_error_contact=float(co["shape_error"].max()), solve_time_contact_s=co["solve_time"])
            rows.append(row)
    return rows


#: The errors the selection bounds (those present in the rows): the test tip error and, with contact, the
#: contact tip error.
SELECTION_KEYS = ("tip_error_test", "tip_error_contact")
_FAMILY_ORDER = {"dvs": 0, "chebyshev": 1, "pcc": 2}


def within(row, tolerance, keys=SELECTION_KEYS):
    """Whether every error ``keys`` of ``row`` (those present) is at most ``tolerance`` (a fraction of L)."""
    return all(row[k] <= tolerance for k in keys if k in row)


#: Median times per solve within this fraction of the fastest qualifying model's count as a tie (the noise of
#: repeated medians on a loaded machine is a few percent; models of equal size differ by less).
TIME_BAND = 0.1


def cheapest(rows, tolerance, keys=SELECTION_KEYS):
    """The selection rule of the trade (the one used by the table, the verdict and ``soro trade``).

    Among the rows :func:`within` the tolerance, the fastest by median time per solve; times within
    :data:`TIME_BAND` of the fastest, or within the two rows' measured spreads (``solve_iqr_s``, the IQR of
    the repeats, where a row has one) of it, count as a tie, resolved by fewer modes, then fewer beam pieces
    (``segments``, where the rows have them: the cantilever's), then the smaller worst
    error of ``keys``, then the family order dvs, chebyshev, pcc. Returns None if no row qualifies. (Medians
    of sub-millisecond solves wander by more than 10 % on a loaded machine: two one-mode beams whose medians
    differed by more than the band in one run of CI and less in the next swapped places; their spreads
    overlapped in both.)"""
    if isinstance(tolerance, bool) or not isinstance(tolerance, (int, float)) or not tolerance > 0:
        raise ParameterError(f"the tolerance is a positive fraction of the length, got {tolerance!r}")
    ok = [r for r in rows if within(r, tolerance, keys)]
    if not ok:
        return None
    first = min(ok, key=lambda r: r["solve_time_s"])
    fastest, spread = first["solve_time_s"], _spread(first)
    tied = [r for r in ok if r["solve_time_s"] - fastest <= max(TIME_BAND * fastest, spread + _spread(r))]
    return min(tied, key=lambda r: (r["modes"], r.get("segments", 0), max(r[k] for k in keys if k in r),
                                    _FAMILY_ORDER.get(r["family"], 9)))


def _spread(row):
    """A row's measured spread of its solve time [s] (0 where it has none: one run, or not measured)."""
    v = row.get("solve_iqr_s")
    return float(v) if v is not None and np.isfinite(v) else 0.0


def _tolerance_text(tolerance):
    return f"{100 * tolerance:g} % of the length (tolerance {tolerance:g})"


def trade_table(rows, tolerance=None):
    """The trade rows as a text table (errors in % of the length, time in ms). With ``tolerance``, a column
    says which rows are within it and the row :func:`cheapest` selects is marked ``<- selected``."""
    contact = bool(rows) and "tip_error_contact" in rows[0]
    pick = cheapest(rows, tolerance) if tolerance is not None else None
    head = f"{'family':<10} {'modes':>5} {'tip train %':>12} {'tip test %':>11} {'shape test %':>13} {'solve ms':>9}"
    if contact:
        head += f" {'tip contact %':>14} {'shape contact %':>16}"
    if tolerance is not None:
        head += f" {'within':>6}"
    lines = [head, "-" * len(head)]
    for r in rows:
        line = (f"{r['family']:<10} {r['modes']:>5} {100 * r['tip_error_train']:>12.3f} "
                f"{100 * r['tip_error_test']:>11.3f} {100 * r['shape_error_test']:>13.3f} "
                f"{1e3 * r['solve_time_s']:>9.3f}")
        if contact:
            line += f" {100 * r['tip_error_contact']:>14.3f} {100 * r['shape_error_contact']:>16.3f}"
        if tolerance is not None:
            line += f" {'yes' if within(r, tolerance) else 'no':>6}" + ("  <- selected" if r is pick else "")
        lines.append(line)
    return "\n".join(lines)


def trade_text(rows, tolerance):
    """The table (:func:`trade_table`) and the verdict of :func:`cheapest`, as ``soro trade`` prints them and
    ``trade.txt`` holds them. Returns (text, selected row or None)."""
    pick = cheapest(rows, tolerance)
    bound = " and ".join(k.replace("tip_error_", "") for k in SELECTION_KEYS if rows and k in rows[0])
    verdict = (f"cheapest within {_tolerance_text(tolerance)} on the {bound} tip error: {pick['family']} with "
               f"{pick['modes']} modes ({1e3 * pick['solve_time_s']:.3f} ms per solve, median)" if pick else
               f"no model reaches {_tolerance_text(tolerance)}")
    return trade_table(rows, tolerance) + "\n\n" + verdict, pick


def trade_figure(rows, tolerance, pick=None):
    """Worst test tip error (with contact, if any) vs median time per solve, log-log: one line per family
    through its models in order of time (no zig-zag), the tolerance dotted, the selected model circled.
    Returns a matplotlib ``Figure`` (not attached to pyplot)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6, 4))
    ax = fig.add_subplot()

    def worst(row):
        return max(100 * max(row[k] for k in SELECTION_KEYS if k in row), 1e-6)
    for fam, mk in (("dvs", "o-"), ("chebyshev", "s-"), ("pcc", "^-")):
        r = sorted((row for row in rows if row["family"] == fam), key=lambda row: row["solve_time_s"])
        if not r:
            continue
        ax.loglog([row["solve_time_s"] * 1e3 for row in r], [worst(row) for row in r], mk, label=fam)
        for row in r:
            ax.annotate(str(row["modes"]), (row["solve_time_s"] * 1e3, worst(row)), fontsize=7)
    if pick is not None:
        ax.loglog([pick["solve_time_s"] * 1e3], [worst(pick)], "o", ms=12, mfc="none", mec="k",
                  label=f"selected: {pick['family']} {pick['modes']}")
    ax.axhline(100 * tolerance, color="k", lw=0.8, ls=":")
    ax.set_xlabel("static solve [ms] (median)")
    ax.set_ylabel("tip error on the test data [% of L]" + (" (worst with contact)" if rows and
                                                            "tip_error_contact" in rows[0] else ""))
    ax.set_title(f"speed-accuracy trade (labels: modes; dotted: tolerance {tolerance:g})")
    ax.legend()
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    return fig


def trade_report(train, test, make_shapes, inputs, out, tolerance=0.03, **kw):
    """:func:`trade`, then its table and verdict (``trade.txt``, :func:`trade_text`), a PNG of the test tip error
    vs the time per solve (``trade.png``; each family one line through its models in order of time) in ``out``.
    Returns (rows, selected)."""
    from sorofem.io import atomic_path

    cheapest([], tolerance)  # refuse a bad tolerance before the work
    rows = trade(train, test, make_shapes, inputs, **kw)
    text, pick = trade_text(rows, tolerance)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    with atomic_path(out / "trade.txt") as tmp:
        Path(tmp).write_text(text + "\n")
    fig = trade_figure(rows, tolerance, pick)
    with atomic_path(out / "trade.png") as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    return rows, pick


def trade_files(train_path, test_path, backbone, inputs=None, out="out/trade", tolerance=0.03, samples=81,
                test_steps=None, **kw):
    """The trade (:func:`trade_report`) from two snapshot files (training and test cases) and a backbone: the
    beam models start at the backbone's first frame, with a 10 mm x 10 mm section of a 1 MPa material (the
    stiffness scale is absorbed by the identified actuation of each model). ``inputs`` default to the first
    input of the training file. Returns (rows, selected, table text)."""
    from sorofem import materials, sdf
    from soroshapes import Shapes

    train = recover_strains(train_path, backbone, samples=samples)
    test = recover_strains(test_path, backbone, samples=samples, steps=test_steps)
    inputs = [sorted(train.inputs)[0]] if inputs is None else list(inputs)
    g0 = np.eye(4)
    g0[:3, :3] = backbone.frames([0.0])[0]
    g0[:3, 3] = backbone.positions([0.0])[0]
    mat = materials.NeoHookean(E=1e6, nu=0.45, density=1000.0)

    def make(bases, dofs):
        return Shapes(bases, dofs, length=backbone.length, section=sdf.Rectangle(0.01, 0.01), material=mat, base=g0,
                      damping=0.0, segments=40)
    rows, pick = trade_report(train, test, make, inputs, out, tolerance=tolerance, **kw)
    return rows, pick, trade_text(rows, tolerance)[0]


def run_trade(train=None, test=None, backbone=None, inputs=None, tolerance=0.03, out=None, quick=False,
              stream=None):
    """``soro trade``: the speed-accuracy table for two snapshot files along a backbone, or for the PneuNet
    demo when no file is given. Prints the table; returns the exit status (1 if no model meets the
    tolerance, 2 for bad arguments)."""
    stream = stream or sys.stdout
    if isinstance(tolerance, bool) or not isinstance(tolerance, (int, float)) or not 0 < tolerance < 1:
        print(f"soro trade: --tolerance is a fraction of the length in (0, 1), e.g. 0.03; got {tolerance}",
              file=sys.stderr)
        return 2
    if train is None:
        if test is not None or backbone is not None:
            print("soro trade: give both TRAIN and TEST snapshot files with --backbone, or none", file=sys.stderr)
            return 2
        from .demo import run_demo

        out = Path(out or "out")
        report = run_demo("dvs_pneunet", out=out, quick=quick, tolerance=tolerance)
        text, pick = trade_text(report["trade"], tolerance)   # the one selection rule, as in trade.txt
        print(text, file=stream)
    else:
        from sorofem.errors import SoroError
        from soroshapes.dvs import Backbone
        if test is None or backbone is None:
            print("soro trade: TRAIN needs a TEST file and --backbone", file=sys.stderr)
            return 2
        try:
            points = [[float(v) for v in p.split(",")] for p in backbone.split(":")]
            rows, pick, text = trade_files(train, test, Backbone(points), inputs=inputs, tolerance=tolerance,
                                           out=Path(out or "out/trade"))
        except (ValueError, SoroError) as e:
            print(f"soro trade: {e}", file=sys.stderr)
            return 2
        print(text, file=stream)
    if pick is None:
        return 1
    print(f"selected: {pick['family']} with {pick['modes']} modes", file=stream)
    return 0
