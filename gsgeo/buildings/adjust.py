"""Planarity adjustment: measured vertices moved, by weighted least squares, onto exact planes.

The model is a Gauss-Helmert adjustment with constraints (solved through Lagrange multipliers):

- observations ``l`` (n, 3): the measured vertices in a local Cartesian frame, metres;
  weights: the inverse of each vertex's 3x3 covariance (m²);
- unknowns: the adjusted vertices ``x`` (n, 3) and, per plane, a unit normal ``u`` and an
  offset ``d`` (the plane is u·x = d); optionally one common eave height ``h``;
- conditions: u_p·x_i - d_p = 0 for every vertex i of plane p; |u_p|² = 1; u_p,z = 0 for
  vertical planes (walls); x_i,z - h = 0 for every eave vertex (``horizontal_eaves``);
  u_a·u_b = 0 for two walls meeting at a right angle (``rectangular``).

A vertex on several planes (a shared corner or ridge end) is one unknown, so shared vertices
stay shared. Plane-times-vertex is bilinear, so the linearised normal equations are iterated
(Gauss-Newton on the Lagrangian) until the corrections stop changing.

The covariance of the adjusted vertices is the vertex block of the inverse of the bordered
(KKT) matrix at convergence: first-order propagation of the observations' covariance through
the adjustment, ``Σx̂ = Σ - Σ Aᵀ (A Σ Aᵀ)⁻¹ A Σ`` in the linear case. It is the full joint
covariance (3n x 3n): adjusted vertices on one plane are correlated.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gsgeo.errors import GeometryError
from gsgeo.solve.linalg import FloatArray
from gsgeo.solve.stats import chi2_sf

MAX_ITERATIONS = 60
#: Convergence: largest change of a vertex (m) and of a normal's component in one iteration.
TOLERANCE = 1e-10


@dataclass(frozen=True)
class PlaneSet:
    """Which vertices lie on a common plane. ``vertical``: the plane is a wall (u_z = 0)."""

    vertices: tuple[int, ...]
    vertical: bool = False


@dataclass(frozen=True)
class Constraints:
    """Everything the adjustment enforces on the vertices.

    ``planes``: the planes; ``eaves``: vertices given one common height (empty: none);
    ``right_angles``: pairs of (vertical) plane indices whose normals are perpendicular.
    """

    planes: tuple[PlaneSet, ...]
    eaves: tuple[int, ...] = ()
    right_angles: tuple[tuple[int, int], ...] = ()


@dataclass
class Adjusted:
    """The result: adjusted vertices ``xyz`` (n, 3) in the frame of the observations, their
    joint covariance ``cov`` (3n, 3n; vertex i's block at rows 3i..3i+2), the planes
    ``planes`` (m, 4: unit normal, offset), the eave height (None without that constraint),
    the weighted sum of squared corrections ``omega`` with its degrees of freedom ``dof``, the
    a-posteriori standard deviation of unit weight ``sigma0`` and the global test's p-value."""

    xyz: FloatArray
    cov: FloatArray
    planes: FloatArray
    eave_height: float | None
    omega: float
    dof: int
    sigma0: float
    p: float
    iterations: int


def fit_plane(x: FloatArray, vertical: bool = False) -> FloatArray:
    """A plane (u, d) through points ``x`` (k, 3), starting values: a roof ring's Newell normal
    (turned up); for a wall, the vertical plane through the chain's first and last points."""
    c = x.sum(axis=0) / x.shape[0]
    if vertical:
        t = x[-1, :2] - x[0, :2]
        u = np.array([-t[1], t[0], 0.0])
    else:
        y = np.roll(x, -1, axis=0)
        u = np.array([np.dot(x[:, 1] - y[:, 1], x[:, 2] + y[:, 2]),
                      np.dot(x[:, 2] - y[:, 2], x[:, 0] + y[:, 0]),
                      np.dot(x[:, 0] - y[:, 0], x[:, 1] + y[:, 1])])
        if u[2] < 0:
            u = -u
    size = float(np.sqrt(u @ u))
    if size == 0.0:
        raise GeometryError("a face's points are collinear: it has no plane")
    u = u / size
    return np.array([u[0], u[1], u[2], float(u @ c)], dtype=np.float64)


def _check_covariances(cov: FloatArray) -> FloatArray:
    """The inverse covariances (weights), or GeometryError for a singular one."""
    try:
        return np.asarray(np.linalg.inv(cov), dtype=np.float64)
    except np.linalg.LinAlgError:
        raise GeometryError("a point's covariance is singular: give each roof point a "
                            "covariance with positive variances") from None


def adjust(l: FloatArray, cov: FloatArray, constraints: Constraints, *,
           covariance: bool = True) -> Adjusted:
    """Adjust the observed vertices ``l`` (n, 3; metres, local frame) with covariances ``cov``
    (n, 3, 3; m²) so that every constraint holds exactly; see the module docstring.

    ``covariance=False`` skips the adjusted vertices' covariance (``cov`` is then empty).
    Raises GeometryError when the constraints cannot all be met (a plane through too few or
    collinear points, constraints that contradict each other).
    """
    n = l.shape[0]
    planes = constraints.planes
    npl = len(planes)
    eaves = np.asarray(constraints.eaves, dtype=np.int64)
    has_h = eaves.size > 0
    nx = 3 * n
    col_p = nx
    nunk = nx + 4 * npl + (1 if has_h else 0)
    col_h = nunk - 1
    n_vert = sum(1 for p in planes if p.vertical)
    m = (sum(len(p.vertices) for p in planes) + npl + n_vert + eaves.size
         + len(constraints.right_angles))
    dof = m - 4 * npl - (1 if has_h else 0)

    weights = _check_covariances(cov)
    w_full = np.zeros((nx, nx))
    for i in range(n):
        w_full[3 * i:3 * i + 3, 3 * i:3 * i + 3] = weights[i]

    x = l.copy()
    par = np.array([fit_plane(l[list(p.vertices)], p.vertical) for p in planes]).reshape(npl, 4)
    h = float(l[eaves, 2].mean()) if has_h else 0.0
    if has_h:
        x[eaves, 2] = h

    # The Jacobian's pattern is fixed; its rows: plane-vertex conditions, unit normals,
    # vertical normals, eave heights, right angles.
    pv_plane = np.concatenate([np.full(len(p.vertices), j, dtype=np.int64)
                               for j, p in enumerate(planes)])
    pv_vertex = np.concatenate([np.asarray(p.vertices, dtype=np.int64) for p in planes])
    n_pv = pv_plane.size
    rows_pv = np.arange(n_pv)[:, None]
    xcols = 3 * pv_vertex[:, None] + np.arange(3)
    pcols = col_p + 4 * pv_plane[:, None] + np.arange(3)
    rows_n = n_pv + np.arange(npl)
    ncols = col_p + 4 * np.arange(npl)[:, None] + np.arange(3)
    vertical = np.array([j for j, p in enumerate(planes) if p.vertical], dtype=np.int64)
    rows_v = n_pv + npl + np.arange(n_vert)
    rows_e = n_pv + npl + n_vert + np.arange(eaves.size)
    rows_r = n_pv + npl + n_vert + eaves.size
    a = np.zeros((m, nunk))
    c = np.zeros(m)
    a[np.arange(n_pv), col_p + 4 * pv_plane + 3] = -1.0
    a[rows_v, col_p + 4 * vertical + 2] = 1.0
    a[rows_e, 3 * eaves + 2] = 1.0
    if has_h:
        a[rows_e, col_h] = -1.0
    kkt = np.zeros((nunk + m, nunk + m))
    kkt[:nx, :nx] = w_full
    iterations = 0
    for _ in range(MAX_ITERATIONS):
        iterations += 1
        u = par[pv_plane, :3]
        xv = x[pv_vertex]
        a[rows_pv, xcols] = u
        a[rows_pv, pcols] = xv
        c[:n_pv] = np.einsum("ij,ij->i", xv, u) - par[pv_plane, 3]
        a[rows_n[:, None], ncols] = par[:, :3]
        c[rows_n] = 0.5 * (np.einsum("ij,ij->i", par[:, :3], par[:, :3]) - 1.0)
        c[rows_v] = par[vertical, 2]
        c[rows_e] = x[eaves, 2] - h
        for k, (pa, pb) in enumerate(constraints.right_angles):
            a[rows_r + k, col_p + 4 * pa:col_p + 4 * pa + 3] = par[pb, :3]
            a[rows_r + k, col_p + 4 * pb:col_p + 4 * pb + 3] = par[pa, :3]
            c[rows_r + k] = par[pa, :3] @ par[pb, :3]
        kkt[:nunk, nunk:] = a.T
        kkt[nunk:, :nunk] = a
        rhs = np.zeros(nunk + m)
        rhs[:nx] = -(w_full @ (x - l).ravel())
        rhs[nunk:] = -c
        try:
            step = np.linalg.solve(kkt, rhs)
        except np.linalg.LinAlgError:
            raise GeometryError("the roof's planes cannot be fitted: a face's points are "
                                "collinear or the constraints contradict each other") from None
        dx = step[:nx].reshape(n, 3)
        dpar = step[nx:nx + 4 * npl].reshape(npl, 4)
        x += dx
        par += dpar
        if has_h:
            h += float(step[col_h])
        if max(float(np.abs(dx).max(initial=0.0)), float(np.abs(dpar[:, :3]).max(initial=0.0))) \
                < TOLERANCE:
            break
    else:
        raise GeometryError("the planarity adjustment does not converge: the roof faces are "
                            "far from planar or the faces do not fit together")
    if not np.all(np.isfinite(x)):
        raise GeometryError("the planarity adjustment diverged")

    cov_x = np.zeros((0, 0))
    if covariance:
        unit = np.zeros((nunk + m, nx))
        unit[:nx, :nx] = np.eye(nx)
        cov_x = np.linalg.solve(kkt, unit)[:nx]
        cov_x = 0.5 * (cov_x + cov_x.T)
    v = (x - l)
    omega = float(np.einsum("ni,nij,nj->", v, weights, v))
    p_value = float(chi2_sf(omega, dof)) if dof > 0 else 1.0
    sigma0 = float(np.sqrt(omega / dof)) if dof > 0 else float("nan")
    return Adjusted(xyz=x, cov=cov_x, planes=par, eave_height=h if has_h else None,
                    omega=omega, dof=dof, sigma0=sigma0, p=p_value, iterations=iterations)


@dataclass(frozen=True)
class PlaneTest:
    """The test of one face on its own: do its points lie on one plane within their sigmas?

    ``chi2`` = Σ vᵢᵀ Σᵢ⁻¹ vᵢ of the corrections that put the face's points on their best plane,
    with ``dof`` = points - 3 (points - 2 for a vertical plane) and its upper-tail ``p``;
    ``worst`` the index (into the face) of the point farthest from that plane in units of its
    sigma along the normal, ``offset`` that distance (m) and ``ratio`` in sigmas; ``rms`` the
    root mean square of the corrections' lengths (m)."""

    chi2: float
    dof: int
    p: float
    worst: int
    offset: float
    ratio: float
    rms: float


def plane_test(l: FloatArray, cov: FloatArray, vertical: bool = False) -> PlaneTest:
    """Fit one plane to the points ``l`` (k, 3; metres) weighted by ``cov`` (k, 3, 3; m²).

    The same Gauss-Helmert model as ``adjust`` with a single plane, the corrections eliminated:
    each point's condition uᵀxᵢ - d = 0 gets the weight qᵢ = 1 / (uᵀΣᵢu), and the plane's
    (u, d) is solved from a 4x4 system bordered by |u| = 1 (and u_z = 0 for a wall)."""
    k = l.shape[0]
    par = fit_plane(l, vertical)
    x = l.copy()
    ncon = 2 if vertical else 1
    dof = k - (2 if vertical else 3)
    omega = 0.0
    for _ in range(MAX_ITERATIONS):
        u, d = par[:3], par[3]
        q = 1.0 / np.maximum(np.einsum("i,nij,j->n", u, cov, u), 1e-300)
        a = np.column_stack([x, -np.ones(k)])
        w = l @ u - d
        n = np.zeros((4 + ncon, 4 + ncon))
        n[:4, :4] = (a * q[:, None]).T @ a
        n[:3, 4] = n[4, :3] = u
        rhs = np.zeros(4 + ncon)
        rhs[:4] = -(a.T @ (q * w))
        rhs[4] = 0.5 * (1.0 - float(u @ u))
        if vertical:
            n[2, 5] = n[5, 2] = 1.0
            rhs[5] = -u[2]
        try:
            dp = np.linalg.solve(n, rhs)[:4]
        except np.linalg.LinAlgError:
            raise GeometryError("a face's points are collinear: it has no plane") from None
        lam = q * (w + a @ dp)
        v = -lam[:, None] * np.einsum("nij,j->ni", cov, u)
        x = l + v
        par = par + dp
        omega = float(np.sum(q * (w + a @ dp) ** 2))
        if float(np.abs(dp[:3]).max()) < TOLERANCE:
            break
    else:
        raise GeometryError("the plane fit of a face does not converge")
    u, d = par[:3], par[3]
    w = l @ u - d
    var = np.einsum("i,nij,j->n", u, cov, u)
    ratio = np.abs(w) / np.sqrt(np.maximum(var, 1e-300))
    worst = int(np.argmax(ratio))
    rms = float(np.sqrt(np.mean(np.sum((x - l) ** 2, axis=1))))
    p = float(chi2_sf(omega, dof)) if dof > 0 else 1.0
    return PlaneTest(chi2=omega, dof=dof, p=p, worst=worst, offset=float(w[worst]),
                     ratio=float(ratio[worst]), rms=rms)


def correction_ratios(l: FloatArray, cov: FloatArray, x: FloatArray) -> FloatArray:
    """Each vertex's squared correction in its own metric, vᵢᵀ Σᵢ⁻¹ vᵢ (n,)."""
    v = x - l
    return np.einsum("ni,nij,nj->n", v, np.linalg.inv(cov), v)

