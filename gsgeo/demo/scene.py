"""The demo scene as analytic geometry, with its 20 validation points (the ground truth).

One frame throughout: the scene's local frame, x east, y north, z up, metres, origin on the
ground at the scene centre. The demo tileset places it as grid coordinates minus an offset
(`gsgeo.demo.place`), so x, y, z are easting, northing and height differences.

Objects (the cases of Deng & Qin, ISPRS 2026):

- textured flat ground, z = 0, over the square |x|, |y| <= GROUND_HALF;
- a building 10 m x 7 m with sharp eaves at 5 m and a pitched roof, ridge 7.5 m along x;
- three thin poles (lamp posts, 8 cm thick, 4 m tall) and a railing (5 cm posts, 1.1 m);
- a low angular sculpture: a wedge-topped block turned 30 degrees, corners 0.25-0.60 m high.

The validation points are features an operator can aim at: centres of checker targets on
the ground and roof, building corners, the centres of pole and post tops, and the top corners
of the sculpture. `first_hit` (ray casting against the solids) is the visibility model of the
accuracy experiment; `surface_height` is the 2.5-D top surface (what a DSM of it records).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

#: Half size of the ground square (m).
GROUND_HALF = 20.0

#: Building footprint, eaves and ridge heights (m).
BUILDING_X = (-14.0, -4.0)
BUILDING_Y = (2.0, 9.0)
EAVES_Z = 5.0
RIDGE_Z = 7.5
RIDGE_Y = 5.5

#: Poles: centres (x, y), radius and height (m).
POLES_XY = ((3.0, -8.0), (9.0, -8.0), (15.0, -8.0))
POLE_RADIUS = 0.04
POLE_HEIGHT = 4.0

#: Railing along y = RAIL_Y, posts every 2 m from x = -12 to -2.
RAIL_Y = -12.0
RAIL_POSTS_X = tuple(float(x) for x in np.arange(-12.0, -1.0, 2.0))
RAIL_POST_RADIUS = 0.025
RAIL_POST_HEIGHT = 1.1
RAIL_RADIUS = 0.02
RAIL_HEIGHTS = (1.05, 0.55)  # centre lines of the top and middle rails

#: Sculpture: centre, turn (degrees, counter-clockwise), half sizes along its own u, v, and the
#: top plane z = SCULPT_Z0 + SCULPT_DZ * u (a wedge, low at u = -a, high at u = +a).
SCULPT_CENTRE = (6.0, 6.0)
SCULPT_TURN_DEG = 30.0
SCULPT_HALF = (0.8, 0.45)
SCULPT_Z0 = 0.425
SCULPT_DZ = 0.35 / 1.6

#: Checker target radius (m) on the ground and on the roof.
TARGET_RADIUS = 0.25


@dataclass(frozen=True)
class ValidationPoint:
    """A ground-truth point: id, subset, position (scene frame, m) and how it is marked.

    kind "target": the centre of a black/white checker disc lying on a surface of unit normal
    ``normal``; kind "corner": a sharp corner or the centre of a pole top (marked with a small
    coloured dot in the splat scene).
    """

    id: str
    subset: str
    xyz: tuple[float, float, float]
    kind: str
    normal: tuple[float, float, float] | None
    description: str


def _unit(v: ArrayLike) -> tuple[float, float, float]:
    v = np.asarray(v, float)
    x, y, z = (float(c) for c in v / np.linalg.norm(v))
    return (x, y, z)


def _sculpture_frame() -> tuple[np.ndarray, np.ndarray]:
    a = np.radians(SCULPT_TURN_DEG)
    return np.array([np.cos(a), np.sin(a)]), np.array([-np.sin(a), np.cos(a)])


def sculpture_corners() -> np.ndarray:
    """The 4 top corners (4, 3) of the sculpture, in the order (-u,-v), (+u,-v), (+u,+v), (-u,+v)."""
    u, v = _sculpture_frame()
    a, b = SCULPT_HALF
    out = []
    for su, sv in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
        xy = np.asarray(SCULPT_CENTRE) + su * a * u + sv * b * v
        out.append([xy[0], xy[1], SCULPT_Z0 + SCULPT_DZ * su * a])
    return np.array(out)


def _roof_normal_south() -> tuple[float, float, float]:
    slope = (RIDGE_Z - EAVES_Z) / (RIDGE_Y - BUILDING_Y[0])
    return _unit([0.0, -slope, 1.0])


def _validation_points() -> tuple[ValidationPoint, ...]:
    x0, x1 = BUILDING_X
    y0, y1 = BUILDING_Y
    up = (0.0, 0.0, 1.0)
    pts = [
        ValidationPoint("G1", "targets", (0.0, -2.0, 0.0), "target", up, "ground target"),
        ValidationPoint("G2", "targets", (14.0, 6.0, 0.0), "target", up, "ground target"),
        ValidationPoint("G3", "targets", (-17.0, -5.0, 0.0), "target", up, "ground target"),
        ValidationPoint("G4", "targets", (2.0, 15.0, 0.0), "target", up, "ground target"),
    ]
    rz = EAVES_Z + (RIDGE_Z - EAVES_Z) * 0.5
    pts.append(ValidationPoint("R1", "targets", (-9.0, (y0 + RIDGE_Y) / 2, rz), "target",
                               _roof_normal_south(), "roof target, south slope"))
    for i, (x, y, what) in enumerate([(x0, y0, "south-west"), (x1, y0, "south-east"),
                                      (x1, y1, "north-east"), (x0, y1, "north-west")], 1):
        pts.append(ValidationPoint(f"B{i}", "building corners", (x, y, EAVES_Z), "corner", None,
                                   f"eaves corner, {what}"))
    pts.append(ValidationPoint("B5", "building corners", (x0, RIDGE_Y, RIDGE_Z), "corner", None,
                               "ridge end, west gable"))
    pts.append(ValidationPoint("B6", "building corners", (x1, RIDGE_Y, RIDGE_Z), "corner", None,
                               "ridge end, east gable"))
    for i, (x, y) in enumerate(POLES_XY, 1):
        pts.append(ValidationPoint(f"T{i}", "thin poles", (x, y, POLE_HEIGHT), "corner", None,
                                   "lamp post top, centre"))
    for i, x in enumerate((RAIL_POSTS_X[0], RAIL_POSTS_X[-1]), 4):
        pts.append(ValidationPoint(f"T{i}", "thin poles", (x, RAIL_Y, RAIL_POST_HEIGHT), "corner",
                                   None, "railing end post top, centre"))
    for i, c in enumerate(sculpture_corners(), 1):
        pts.append(ValidationPoint(f"S{i}", "low corners", (float(c[0]), float(c[1]), float(c[2])), "corner",
                                   None, f"sculpture top corner, {c[2]:.2f} m above ground"))
    return tuple(pts)


#: The 20 validation points (ground truth, scene frame).
VALIDATION_POINTS: tuple[ValidationPoint, ...] = _validation_points()
#: Subsets in table order.
SUBSETS = ("targets", "building corners", "thin poles", "low corners")


def truth_array() -> np.ndarray:
    """Validation point positions (20, 3), scene frame, metres."""
    return np.array([p.xyz for p in VALIDATION_POINTS], dtype=np.float64)


# --- solids and ray casting -------------------------------------------------------------------

@dataclass(frozen=True)
class ConvexSolid:
    """The convex polyhedron {p : n_k . p <= d_k} given by planes (K, 4) rows (n_k, d_k)."""

    name: str
    planes: np.ndarray


@dataclass(frozen=True)
class Cylinder:
    """A solid finite cylinder: axis from ``a`` to ``b`` (m), ``radius`` (m)."""

    name: str
    a: np.ndarray
    b: np.ndarray
    radius: float


def _building() -> ConvexSolid:
    x0, x1 = BUILDING_X
    y0, y1 = BUILDING_Y
    s = (RIDGE_Z - EAVES_Z) / (RIDGE_Y - y0)
    # z <= EAVES + s (y - y0)  ->  -s y + z <= EAVES - s y0 ; z <= EAVES + s (y1 - y) -> s y + z <= ...
    planes = np.array([
        [-1, 0, 0, -x0], [1, 0, 0, x1], [0, -1, 0, -y0], [0, 1, 0, y1], [0, 0, -1, 0],
        [0, -s, 1, EAVES_Z - s * y0], [0, s, 1, EAVES_Z + s * y1],
    ], dtype=np.float64)
    return ConvexSolid("building", planes)


def _sculpture() -> ConvexSolid:
    u, v = _sculpture_frame()
    c = np.asarray(SCULPT_CENTRE)
    a, b = SCULPT_HALF
    rows = []
    for axis, half in ((u, a), (v, b)):
        for sgn in (1, -1):
            n = sgn * axis
            rows.append([n[0], n[1], 0.0, half + n @ c])
    rows.append([0, 0, -1, 0])
    # z <= Z0 + DZ * ((x, y) - c) . u
    rows.append([-SCULPT_DZ * u[0], -SCULPT_DZ * u[1], 1.0, SCULPT_Z0 - SCULPT_DZ * (u @ c)])
    return ConvexSolid("sculpture", np.array(rows, dtype=np.float64))


def solids() -> list[ConvexSolid | Cylinder]:
    """Every solid of the scene except the ground plane."""
    out: list[ConvexSolid | Cylinder] = [_building(), _sculpture()]
    for i, (x, y) in enumerate(POLES_XY):
        out.append(Cylinder(f"pole{i}", np.array([x, y, 0.0]), np.array([x, y, POLE_HEIGHT]),
                            POLE_RADIUS))
    for i, x in enumerate(RAIL_POSTS_X):
        out.append(Cylinder(f"post{i}", np.array([x, RAIL_Y, 0.0]),
                            np.array([x, RAIL_Y, RAIL_POST_HEIGHT]), RAIL_POST_RADIUS))
    for i, z in enumerate(RAIL_HEIGHTS):
        out.append(Cylinder(f"rail{i}", np.array([RAIL_POSTS_X[0], RAIL_Y, z]),
                            np.array([RAIL_POSTS_X[-1], RAIL_Y, z]), RAIL_RADIUS))
    return out


def _hit_convex(s: ConvexSolid, o: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Entry parameter t (M,) of rays o + t d into a convex solid (inf when missed)."""
    n, dk = s.planes[:, :3], s.planes[:, 3]
    den = d @ n.T                      # (M, K)
    num = dk[None, :] - o @ n.T        # (M, K): inside where num >= 0 at t = 0
    with np.errstate(divide="ignore", invalid="ignore"):
        t = num / den
    t_in = np.where(den < 0, t, -np.inf).max(axis=1)
    t_out = np.where(den > 0, t, np.inf).min(axis=1)
    parallel_out = ((den == 0) & (num < 0)).any(axis=1)
    hit = (t_in <= t_out) & (t_out >= 0) & ~parallel_out
    return np.where(hit, np.maximum(t_in, 0.0), np.inf)


def _hit_cylinder(c: Cylinder, o: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Entry parameter t (M,) of rays o + t d into a solid finite cylinder (inf when missed)."""
    axis = c.b - c.a
    length = float(np.linalg.norm(axis))
    u = axis / length
    w = o - c.a
    du, wu = d @ u, w @ u
    dp = d - du[:, None] * u
    wp = w - wu[:, None] * u
    qa = np.einsum("ij,ij->i", dp, dp)
    qb = 2 * np.einsum("ij,ij->i", dp, wp)
    qc = np.einsum("ij,ij->i", wp, wp) - c.radius**2
    disc = qb * qb - 4 * qa * qc
    best = np.full(len(o), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        sq = np.sqrt(np.where(disc >= 0, disc, np.nan))
        for t in ((-qb - sq) / (2 * qa), (-qb + sq) / (2 * qa)):
            s = wu + t * du
            ok = (t >= 0) & (s >= 0) & (s <= length)
            best = np.where(ok & (t < best), t, best)
        for s_cap in (0.0, length):
            t = (s_cap - wu) / du
            p = wp + t[:, None] * dp
            ok = (t >= 0) & (np.einsum("ij,ij->i", p, p) <= c.radius**2)
            best = np.where(ok & (t < best), t, best)
    return best


def first_hit(origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Parameter t (M,) of the first surface hit by rays origins + t directions (M, 3), over all
    solids and the ground plane z = 0 (inf where none). Units of t: metres for unit directions."""
    o = np.asarray(origins, np.float64).reshape(-1, 3)
    d = np.asarray(directions, np.float64).reshape(-1, 3)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(d[:, 2] < 0, -o[:, 2] / d[:, 2], np.inf)
    t = np.where(t >= 0, t, np.inf)
    for s in solids():
        hit = _hit_convex(s, o, d) if isinstance(s, ConvexSolid) else _hit_cylinder(s, o, d)
        t = np.minimum(t, hit)
    return t


def visible(origins: np.ndarray, targets: np.ndarray, *, tol: float = 1e-3) -> np.ndarray:
    """True where the segment from each origin to its target (M, 3) reaches the target before
    any surface (within ``tol`` metres): the target is seen from there."""
    o = np.asarray(origins, np.float64).reshape(-1, 3)
    p = np.asarray(targets, np.float64).reshape(-1, 3)
    v = p - o
    rng = np.linalg.norm(v, axis=1)
    return first_hit(o, v / rng[:, None]) >= rng - tol


# --- the 2.5-D top surface ------------------------------------------------------------------

def surface_height(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Height (m) of the highest surface above (x, y): what a perfect DSM of the scene records."""
    x = np.asarray(x, np.float64)
    y = np.asarray(y, np.float64)
    z = np.zeros(np.broadcast(x, y).shape)
    x0, x1 = BUILDING_X
    y0, y1 = BUILDING_Y
    inb = (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
    s = (RIDGE_Z - EAVES_Z) / (RIDGE_Y - y0)
    roof = EAVES_Z + s * np.minimum(y - y0, y1 - y)
    z = np.where(inb, np.maximum(z, roof), z)
    u, v = _sculpture_frame()
    dx, dy = x - SCULPT_CENTRE[0], y - SCULPT_CENTRE[1]
    su, sv = dx * u[0] + dy * u[1], dx * v[0] + dy * v[1]
    ins = (np.abs(su) <= SCULPT_HALF[0]) & (np.abs(sv) <= SCULPT_HALF[1])
    z = np.where(ins, np.maximum(z, SCULPT_Z0 + SCULPT_DZ * su), z)
    for px, py in POLES_XY:
        z = np.where((x - px) ** 2 + (y - py) ** 2 <= POLE_RADIUS**2, np.maximum(z, POLE_HEIGHT), z)
    for px in RAIL_POSTS_X:
        inp = (x - px) ** 2 + (y - RAIL_Y) ** 2 <= RAIL_POST_RADIUS**2
        z = np.where(inp, np.maximum(z, RAIL_POST_HEIGHT), z)
    inr = (np.abs(y - RAIL_Y) <= RAIL_RADIUS) & (x >= RAIL_POSTS_X[0]) & (x <= RAIL_POSTS_X[-1])
    z = np.where(inr, np.maximum(z, RAIL_HEIGHTS[0] + RAIL_RADIUS), z)
    return z


def inside(points: np.ndarray) -> np.ndarray:
    """True where points (..., 3) lie inside a solid or below the ground (z < 0)."""
    p = np.asarray(points, np.float64)
    out = p[..., 2] < 0
    for s in solids():
        if isinstance(s, ConvexSolid):
            out |= np.all(p @ s.planes[:, :3].T <= s.planes[:, 3], axis=-1)
        else:
            axis = s.b - s.a
            length = float(np.linalg.norm(axis))
            u = axis / length
            w = p - s.a
            along = w @ u
            radial = w - along[..., None] * u
            out |= ((along >= 0) & (along <= length)
                    & (np.einsum("...i,...i->...", radial, radial) <= s.radius**2))
    return out
