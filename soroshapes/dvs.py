r"""From FEM snapshots to beam models: strain recovery, data-driven strain bases (DVS) and identification.

Strain recovery (the seed's Algorithm 1)
-----------------------------------------
A :class:`Backbone` is a reference curve :math:`\bar\gamma(\sigma)` inside the undeformed body, with frames
:math:`\bar R(\sigma)` whose x axis is its tangent (in 2D the z axis is the out-of-plane normal, so planar
bending is the strain :math:`\kappa_z`). For every snapshot step of a FEM case (:class:`sorofem.snapshots.
Snapshots`, read without DOLFINx), :func:`recover_strains`

1. locates each sample point :math:`\bar\gamma(\sigma_j)` in the linear mesh (barycentric coordinates
   :math:`\lambda_a`; points just outside snap to the nearest cell);
2. takes the deformation gradients of the cells around it (:math:`F = I + \nabla u`, exact and constant on
   linear simplices), fits them by a linear field (weighted least squares over the nearest cells; this
   recovers a smooth gradient, also at the ends of the body where one-sided averages lag) evaluated at the
   point, and its rotation by polar decomposition :math:`F = RU`;
3. forms :math:`g_j = (R_j \bar R_j,\ \bar\gamma_j + \sum_a \lambda_a u_a)` and the strain by a central
   difference on the group, :math:`\xi_j = \log(g_{j-1}^{-1} g_{j+1})^\vee / (\sigma_{j+1} - \sigma_{j-1})`
   (over the first or last two intervals at the ends), exact for constant strain and second-order accurate
   otherwise (first order at the ends).

DVS basis and identification
----------------------------
:func:`dvs_basis` is the snapshot POD of each active strain (weighted by the arc-length quadrature, so that the
modes are orthonormal in :math:`L^2(0, L)`), returned as :class:`~soroshapes.basis.Basis` objects for
:class:`~soroshapes.shapes.Shapes`. :func:`identify` projects the recovered strains on a beam model's basis
(:math:`q_k`) and fits, by linear least squares, the generalized force of each input as a polynomial in the
input, :math:`\tau_i(u) = \sum_d c_{i,d} u^d`, such that :math:`K q_k - f_g(q_k) = \sum_i \tau_i(u_{i,k})` over the
snapshots, and the cavity volumes as quadratic functions of :math:`q`. From pressure data alone the stiffness and
the actuation scale cannot be told apart; the beam keeps the stiffness of its section and material (the fit
absorbs the rest into :math:`\tau`), which is what makes its response to pressure match FEM.

Units: SI (m, rad/m, Pa).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from sorofem._lazy import moved_attributes
from sorofem.errors import DataError, ParameterError

__all__ = ["Backbone", "StrainData", "recover_strains", "dvs_basis", "Identified", "PolynomialForce", "identify",
           "compare", "polar_rotation", "mean_rotation"]

#: The speed-accuracy study moved to the application layer :mod:`soro.trade` (README.md, "Moved names"):
#: importing one of its names from here is an ImportError that names the new place.
MOVED = {name: f"soro.trade.{name}" for name in (
    "trade", "cheapest", "within", "trade_table", "trade_text", "trade_figure", "trade_report", "trade_files",
    "SELECTION_KEYS", "TIME_BAND")}
__getattr__ = moved_attributes(__name__, MOVED)


# ------------------------------------------------------------------------------------------------------------
# rotations
# ------------------------------------------------------------------------------------------------------------
def polar_rotation(F):
    """Rotation factor :math:`R` of :math:`F = RU` for arrays of (3, 3) matrices (SVD; det +1)."""
    U, _, Vt = np.linalg.svd(F)
    d = np.sign(np.linalg.det(U @ Vt))
    U[..., :, -1] *= d[..., None]
    return U @ Vt


def mean_rotation(Rs, weights):
    """Chordal mean of rotations (k, 3, 3) with weights (k,): the SO(3) matrix nearest to their weighted sum."""
    S = np.tensordot(np.asarray(weights, dtype=float), Rs, axes=(0, 0))
    return polar_rotation(S[None])[0]


def _embed3(F):
    """(n, d, d) -> (n, 3, 3) with a unit out-of-plane stretch for d = 2."""
    if F.shape[-1] == 3:
        return F
    out = np.zeros(F.shape[:-2] + (3, 3))
    out[..., :2, :2] = F
    out[..., 2, 2] = 1.0
    return out


# ------------------------------------------------------------------------------------------------------------
# backbone
# ------------------------------------------------------------------------------------------------------------
class Backbone:
    """A reference curve inside the undeformed body: a polyline through ``points`` (m, 2 or 3) [m].

    Frames: x along the tangent; in 2D z is the out-of-plane axis (0, 0, 1); in 3D the y axis starts along
    ``normal`` (projected off the first tangent; default the coordinate axis least aligned with it) and is
    carried along the curve by parallel transport (rotation-minimizing frames).
    """

    def __init__(self, points, normal=None):
        P = np.asarray(points, dtype=float)
        if P.ndim != 2 or P.shape[1] not in (2, 3) or len(P) < 2 or not np.all(np.isfinite(P)):
            raise ParameterError("a backbone needs at least 2 finite points of 2 or 3 coordinates [m]")
        seg = np.linalg.norm(np.diff(P, axis=0), axis=1)
        if np.any(seg <= 0):
            raise ParameterError("backbone points must be distinct (a zero-length segment was given)")
        self.gdim = P.shape[1]
        self.points = np.column_stack([P, np.zeros(len(P))]) if self.gdim == 2 else P
        self.arc = np.concatenate([[0.0], np.cumsum(seg)])
        self.length = float(self.arc[-1])
        self._normal = None if normal is None else np.asarray(normal, dtype=float)

    @classmethod
    def line(cls, start, end, normal=None):
        """The straight segment from ``start`` to ``end`` [m]."""
        return cls(np.array([start, end], dtype=float), normal)

    def positions(self, sigma):
        """Points at arc lengths ``sigma`` [m]: (k, 3)."""
        s = np.clip(np.asarray(sigma, dtype=float), 0.0, self.length)
        return np.column_stack([np.interp(s, self.arc, self.points[:, i]) for i in range(3)])

    def frames(self, sigma):
        """Reference rotations (k, 3, 3) at ``sigma``: columns = body x (tangent), y, z."""
        s = np.clip(np.asarray(sigma, dtype=float), 0.0, self.length)
        seg = np.clip(np.searchsorted(self.arc, s, side="right") - 1, 0, len(self.arc) - 2)
        T = np.diff(self.points, axis=0)
        T /= np.linalg.norm(T, axis=1)[:, None]
        if self.gdim == 2:
            z = np.array([0.0, 0.0, 1.0])
            Ys = np.cross(z, T)
            Zs = np.tile(z, (len(T), 1))
        else:
            n = self._normal
            if n is None:
                n = np.eye(3)[np.argmin(np.abs(T[0]))]
            y = n - (n @ T[0]) * T[0]
            if np.linalg.norm(y) < 1e-9:
                raise ParameterError("the backbone normal is parallel to its first tangent; give another")
            Ys = [y / np.linalg.norm(y)]
            for k in range(1, len(T)):          # parallel transport: rotate y by the rotation taking T[k-1] to T[k]
                a, b = T[k - 1], T[k]
                v, c = np.cross(a, b), float(a @ b)
                yk = Ys[-1]
                if np.linalg.norm(v) > 1e-14:
                    V = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
                    yk = (np.eye(3) + V + V @ V / (1 + c)) @ yk
                yk = yk - (yk @ b) * b
                Ys.append(yk / np.linalg.norm(yk))
            Ys = np.array(Ys)
            Zs = np.cross(T, Ys)
        R = np.stack([T, Ys, Zs], axis=2)
        return R[seg]


# ------------------------------------------------------------------------------------------------------------
# strain recovery
# ------------------------------------------------------------------------------------------------------------
@dataclass
class StrainData:
    """Strains recovered along a backbone: ``sigma`` (m,) [m], ``xi`` (steps, m, 6) and the reference strain
    ``xi0`` (m, 6) (angular part first, rad/m; then stretch/shear), frames ``frames`` (steps, m, 4, 4), the
    snapshot ``times`` (steps,) and ``inputs`` / ``cavity_volumes`` (name -> (steps,)), ``length`` [m]."""

    sigma: np.ndarray
    xi: np.ndarray
    xi0: np.ndarray
    frames: np.ndarray
    times: np.ndarray
    inputs: dict = field(default_factory=dict)
    cavity_volumes: dict = field(default_factory=dict)
    length: float = 0.0

    @property
    def weights(self):
        """Trapezoid quadrature weights of ``sigma`` [m]."""
        w = np.zeros_like(self.sigma)
        h = np.diff(self.sigma)
        w[:-1] += h / 2
        w[1:] += h / 2
        return w

    def positions(self):
        """Backbone positions (steps, m, 3) [m]."""
        return self.frames[:, :, :3, 3]

    def select(self, steps):
        """The same data restricted to snapshot indices ``steps``."""
        steps = np.asarray(steps)
        return StrainData(self.sigma, self.xi[steps], self.xi0, self.frames[steps], self.times[steps],
                          {k: v[steps] for k, v in self.inputs.items()},
                          {k: v[steps] for k, v in self.cavity_volumes.items()}, self.length)

    def project(self, shapes):
        r"""Least-squares coordinates of the recovered strains in ``shapes``' basis (steps, n):
        :math:`\min_q \int_0^L |\Theta q + \xi_\circ - \xi|^2 d\sigma` over its active strains."""
        if abs(shapes.length - self.length) > 1e-9 * self.length:
            raise ParameterError(f"the beam's length {shapes.length:g} m differs from the backbone's "
                                 f"{self.length:g} m")
        Th = shapes.theta(self.sigma)                        # (m, 6, n)
        w = self.weights
        A = np.einsum("m,mri,mrj->ij", w, Th, Th)
        rhs = np.einsum("m,mri,kmr->ki", w, Th, self.xi - self.xi0[None])
        return np.linalg.solve(A, rhs.T).T


def _locate(X, cells, points, tree, edges):
    """Cell index and barycentric coordinates (k, d+1) of each point (nearest cell if outside), from the
    KD-tree of the cell centroids and the cells' edge matrices (n_cells, d, d)."""
    d = X.shape[1]
    _, cand = tree.query(points, k=min(24, len(cells)))
    cand = np.atleast_2d(cand)
    out_c = np.empty(len(points), dtype=int)
    out_l = np.empty((len(points), d + 1))
    for j, p in enumerate(points):
        cs = cand[j]
        lam = np.linalg.solve(edges[cs], (p - X[cells[cs, 0]])[..., None])[..., 0]
        lam = np.column_stack([1 - lam.sum(axis=1), lam])
        best = int(np.argmax(lam.min(axis=1)))
        out_c[j] = cs[best]
        l = np.clip(lam[best], 0.0, None)
        out_l[j] = l / l.sum()
    return out_c, out_l


def _gradient_stencils(cent, vol, points, tree):
    r"""For each point, its nearest cells (k, by centroid) and weights ``beta`` such that
    :math:`F(p) \approx \sum_c \beta_c F_c` is the value at p of the weighted least-squares linear fit of the
    cell values (weights: cell volumes ``vol``)."""
    d = cent.shape[1]
    k = min(10 * (d + 1), len(cent))
    _, nb = tree.query(points, k=k)
    nb = np.atleast_2d(nb)
    beta = np.zeros(nb.shape)
    for j, p in enumerate(points):
        A = np.column_stack([np.ones(k), cent[nb[j]] - p])
        W = vol[nb[j]]
        M = A.T @ (W[:, None] * A)
        try:
            beta[j] = np.linalg.solve(M, (A * W[:, None]).T)[0]
        except np.linalg.LinAlgError:      # cells in a line (degenerate stencil): plain weighted mean
            beta[j] = W / W.sum()
    return nb, beta


def recover_strains(snapshots, backbone, samples=101, steps=None):
    """Strains along ``backbone`` for the snapshot steps (all by default) of a FEM case.

    Parameters
    ----------
    snapshots : :class:`sorofem.snapshots.Snapshots` or path of a snapshot file.
    backbone : :class:`Backbone` inside the undeformed mesh (same dimension).
    samples : int
        Number of equally spaced sample points along the backbone (>= 5).

    Returns
    -------
    :class:`StrainData`
    """
    from scipy.spatial import cKDTree

    from sorofem.snapshots import Snapshots, cell_deformation_gradients

    snap = snapshots if isinstance(snapshots, Snapshots) else Snapshots(snapshots)
    if snap.cell_type not in ("triangle", "tetrahedron"):
        raise DataError(f"strain recovery needs simplex meshes (triangles, tetrahedra), got {snap.cell_type}")
    if backbone.gdim != snap.gdim:
        raise ParameterError(f"a {backbone.gdim}D backbone for a {snap.gdim}D mesh")
    samples = int(samples)
    if samples < 5:
        raise ParameterError("use at least 5 samples along the backbone")
    sigma = np.linspace(0.0, backbone.length, samples)
    P = backbone.positions(sigma)
    Rref = backbone.frames(sigma)
    X, cells = snap.vertices, snap.cells
    d = snap.gdim
    edges = np.swapaxes(X[cells[:, 1:]] - X[cells[:, :1]], 1, 2)       # (n_cells, d, d)
    cent = X[cells].mean(axis=1)
    tree = cKDTree(cent)
    cidx, lam = _locate(X, cells, P[:, :d], tree, edges)
    # distance of the points to their cells: warn loudly if the backbone leaves the body
    inside = np.einsum("ka,kai->ki", lam, X[cells[cidx]])
    off = np.linalg.norm(inside - P[:, :d], axis=1).max()
    size = np.linalg.norm(X.max(axis=0) - X.min(axis=0))
    if off > 1e-3 * size:
        raise ParameterError(f"the backbone leaves the mesh (a sample lies {off:.3g} m outside); put it inside the "
                             "undeformed body")
    # the deformation gradient at each point: a linear least-squares fit of the (cellwise constant) F of the
    # nearest cells, evaluated at the point -- unbiased at the ends of the body, where one-sided averages lag
    nb, beta = _gradient_stencils(cent, np.abs(np.linalg.det(edges)), P[:, :d], tree)
    need = np.unique(nb)
    where = np.searchsorted(need, nb)
    steps = np.arange(snap.n_steps) if steps is None else np.asarray(steps)
    frames = np.zeros((len(steps), samples, 4, 4))
    for s_i, step in enumerate(steps):
        U = snap.displacement(int(step))
        F = cell_deformation_gradients(X, cells[need], U, snap.cell_type)
        Fp = np.einsum("jc,jcab->jab", beta, F[where])
        R = polar_rotation(_embed3(Fp))
        Ue = np.column_stack([U, np.zeros(len(U))]) if d == 2 else U
        frames[s_i, :, :3, :3] = R @ Rref
        frames[s_i, :, :3, 3] = P + np.einsum("ja,jai->ji", lam, Ue[cells[cidx]])
        frames[s_i, :, 3, 3] = 1.0
    ref = np.zeros((samples, 4, 4))
    ref[:, :3, :3], ref[:, :3, 3], ref[:, 3, 3] = Rref, P, 1.0
    xi0 = _group_difference(ref[None], sigma)[0]
    xi = _group_difference(frames, sigma)
    return StrainData(sigma=sigma, xi=xi, xi0=xi0, frames=frames, times=snap.times[steps],
                      inputs={k: v[steps] for k, v in snap.inputs.items()},
                      cavity_volumes={k: v[steps] for k, v in snap.cavity_volumes.items()},
                      length=backbone.length)


def _group_difference(frames, sigma):
    r"""Strains (steps, m, 6) of frame sequences (steps, m, 4, 4) by central differences on SE(3),
    :math:`\log(g_{j-1}^{-1} g_{j+1})^\vee / (\sigma_{j+1} - \sigma_{j-1})`; at an end the difference over its
    first two intervals, :math:`\log(g_0^{-1} g_2)^\vee / (\sigma_2 - \sigma_0)` (first order, but over
    samples of the same parity: P1 interpolation leaves errors that alternate between neighbouring samples)."""
    from .lie import logSE3

    n_steps, m = frames.shape[:2]
    xi = np.zeros((n_steps, m, 6))
    inv = np.linalg.inv(frames)
    for k in range(n_steps):
        for j in range(m):
            a, b = (j - 1, j + 1) if 0 < j < m - 1 else ((0, min(2, m - 1)) if j == 0 else (max(m - 3, 0), m - 1))
            xi[k, j] = logSE3(np.ascontiguousarray(inv[k, a] @ frames[k, b])) / (sigma[b] - sigma[a])
    return xi


# ------------------------------------------------------------------------------------------------------------
# DVS basis
# ------------------------------------------------------------------------------------------------------------
def dvs_basis(data, dofs, energy=None):
    """Data-driven strain bases: the POD of each strain with ``dofs[i] > 0`` over the snapshots.

    Parameters
    ----------
    data : :class:`StrainData` or a list of them (same backbone samples; their snapshots are pooled)
    dofs : 6 ints
        Number of modes per strain (as the ``dofs`` of :class:`~soroshapes.shapes.Shapes`); with ``energy``
        (a fraction in (0, 1]) they are upper bounds and each strain keeps the fewest modes whose squared
        singular values reach that fraction of the total.

    Returns
    -------
    (bases, dofs, info): a list of 6 :class:`~soroshapes.basis.Basis` (None for fixed strains), orthonormal in
    :math:`L^2(0, L)`, ready for ``Shapes(bases, dofs, ...)``; the numbers of modes kept; ``info`` with the
    singular values and captured energy per strain.
    """
    from .basis import Basis

    dofs = [int(k) for k in dofs]
    if len(dofs) != 6 or min(dofs) < 0 or sum(dofs) == 0:
        raise ParameterError("dofs must be 6 non-negative integers, not all zero")
    if isinstance(data, (list, tuple)):
        if any(len(d.sigma) != len(data[0].sigma) or not np.allclose(d.sigma, data[0].sigma) for d in data):
            raise ParameterError("pooled strain data must share their backbone samples")
        data = StrainData(data[0].sigma, np.concatenate([d.xi for d in data]), data[0].xi0,
                          np.concatenate([d.frames for d in data]), np.concatenate([d.times for d in data]),
                          length=data[0].length)
    if energy is not None and not (0 < energy <= 1):
        raise ParameterError("energy must be a fraction in (0, 1]")
    w = data.weights
    sw = np.sqrt(w)
    s_norm = data.sigma / data.length
    bases, kept, info = [None] * 6, [0] * 6, {}
    for i, k in enumerate(dofs):
        if k == 0:
            continue
        Y = (data.xi[:, :, i] - data.xi0[None, :, i]).T * sw[:, None]       # (m, steps)
        U, S, _ = np.linalg.svd(Y, full_matrices=False)
        tot = float(np.sum(S**2))
        if tot <= 0:
            raise DataError(f"strain {i} never changes in the snapshots: nothing to learn; set dofs[{i}] = 0")
        frac = np.cumsum(S**2) / tot
        if energy is not None:
            k = min(k, int(np.searchsorted(frac, energy - 1e-15) + 1))
        k = min(k, int(np.sum(S > 1e-12 * S[0])))
        modes = U[:, :k] / sw[:, None]
        modes *= np.sign(modes.sum(axis=0) + 1e-300)[None, :]                # a reproducible sign
        bases[i] = Basis.from_data(s_norm, modes).orthonormalize(data.length)
        kept[i] = k
        info[i] = {"singular_values": S.tolist(), "energy": float(frac[k - 1])}
    return bases, tuple(kept), info


# ------------------------------------------------------------------------------------------------------------
# identification
# ------------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PolynomialForce:
    r""":math:`\tau(u) = \sum_{d=1}^{D} c_d u^d` with ``coefficients`` (D, n): an identified actuator."""

    coefficients: np.ndarray

    def __call__(self, u):
        c = self.coefficients
        return sum(c[d] * float(u) ** (d + 1) for d in range(len(c)))


@dataclass
class Identified:
    """What :func:`identify` found: per input, polynomial coefficients ``coefficients[name]`` (degree, n) of
    :math:`\\tau(u) = \\sum_{d \\ge 1} c_d u^d`; the snapshot coordinates ``q`` (steps, n); the relative
    residual of the fit ``fit_error``; per cavity, quadratic volume models ``volume[name](q)`` [m^3]."""

    coefficients: dict
    q: np.ndarray
    fit_error: float
    volume_models: dict = field(default_factory=dict)

    def force(self, name):
        """Generalized force of input ``name`` as a callable ``u -> (n,)`` (picklable: a beam with identified
        actuators can be sent to another process, e.g. a simulated board)."""
        return PolynomialForce(self.coefficients[name])

    def volume(self, name, q):
        """Volume of cavity ``name`` [m^3] at coordinates ``q`` (quadratic fit)."""
        c0, c1, C2 = self.volume_models[name]
        q = np.asarray(q, dtype=float)
        return float(c0 + c1 @ q + q @ C2 @ q)


def identify(shapes, data, inputs=None, degree=3, attach=True):
    r"""Fit the actuation of ``shapes`` to FEM data so that its static response to the inputs matches.

    With the snapshot coordinates :math:`q_k` (:meth:`StrainData.project`) and inputs :math:`u_{i,k}`,
    solves :math:`\min \sum_k |K q_k - f_g(q_k) - \sum_i \sum_{d=1}^{D} c_{i,d} u_{i,k}^d|^2` for the
    :math:`c_{i,d} \in \mathbb R^n` (``degree`` D), and fits each cavity volume as
    :math:`V(q) = v_0 + v_1^T q + q^T V_2 q` (least squares, symmetric :math:`V_2`). With ``attach`` the inputs
    are added to ``shapes`` as actuators (:meth:`~soroshapes.shapes.Shapes.add_actuator`), in the order of
    ``inputs`` (default: every input of the data).
    """
    names = list(data.inputs) if inputs is None else list(inputs)
    for nm in names:
        if nm not in data.inputs:
            raise ParameterError(f"no input {nm!r} in the data; it has {sorted(data.inputs)}")
    degree = int(degree)
    if degree < 1:
        raise ParameterError("degree must be >= 1")
    q = data.project(shapes)
    tau = np.array([shapes.K @ qk - shapes.gravity_force(qk) for qk in q])          # (steps, n)
    U = np.column_stack([data.inputs[nm] for nm in names]) if names else np.zeros((len(q), 0))
    A = np.column_stack([U[:, i] ** (d + 1) for i in range(len(names)) for d in range(degree)]) if names else \
        np.zeros((len(q), 0))
    if A.shape[1] > len(q):
        raise DataError(f"{len(q)} snapshots cannot fit {A.shape[1]} coefficients per coordinate; use more "
                        "load steps or a lower degree")
    coef, *_ = np.linalg.lstsq(A, tau, rcond=None)
    fit = np.linalg.norm(A @ coef - tau) / max(np.linalg.norm(tau), 1e-300)
    coefficients = {nm: coef[i * degree:(i + 1) * degree] for i, nm in enumerate(names)}
    vols = {}
    n = q.shape[1]
    iu = np.triu_indices(n)
    for name, V in data.cavity_volumes.items():
        B = np.column_stack([np.ones(len(q)), q, q[:, iu[0]] * q[:, iu[1]]])
        c, *_ = np.linalg.lstsq(B, V, rcond=None)
        C2 = np.zeros((n, n))
        C2[iu] = c[1 + n:]
        C2 = 0.5 * (C2 + C2.T)
        vols[name] = (float(c[0]), c[1:1 + n], C2)
    ident = Identified(coefficients, q, float(fit), vols)
    if attach:
        for nm in names:
            shapes.add_actuator(ident.force(nm), name=nm)
    return ident


# ------------------------------------------------------------------------------------------------------------
# a beam model against strain data (the speed-accuracy study that uses it is the application's: soro.trade)
# ------------------------------------------------------------------------------------------------------------
def compare(shapes, data, inputs, repeats=5):
    """Errors of a beam model against strain data: for each snapshot, the beam's static shape at the
    snapshot's inputs against the recovered FEM backbone. Returns dict with ``tip_error`` (steps,) and
    ``shape_error`` (steps,) [fractions of the length: tip distance, and the root-mean-square distance of the
    backbone points], ``solve_time`` [s] (the median wall time of one static solve from the straight rod, over
    ``repeats`` solves of every snapshot: one sample varies several-fold on a busy machine), ``solve_times``
    (every sample [s]) and the beam coordinates ``q`` (steps, n)."""
    import time

    if isinstance(repeats, bool) or not isinstance(repeats, int) or repeats < 1:
        raise ParameterError(f"repeats must be a positive integer, got {repeats!r}")
    L = data.length
    fem_pos = data.positions()
    tip, shape, times, qs = [], [], [], []
    for k in range(len(data.times)):
        u = [float(data.inputs[nm][k]) for nm in inputs]
        for _ in range(repeats):
            t0 = time.perf_counter()
            q = shapes.statics(u=u)
            times.append(time.perf_counter() - t0)
        P = shapes.positions(q)
        beam = np.column_stack([np.interp(data.sigma, shapes.sigma, P[:, i]) for i in range(3)])
        tip.append(np.linalg.norm(beam[-1] - fem_pos[k, -1]) / L)
        shape.append(np.sqrt(np.mean(np.sum((beam - fem_pos[k]) ** 2, axis=1))) / L)
        qs.append(q)
    return {"tip_error": np.array(tip), "shape_error": np.array(shape), "solve_time": float(np.median(times)),
            "solve_times": np.array(times), "q": np.array(qs)}
