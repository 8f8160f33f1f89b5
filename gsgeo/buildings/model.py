"""A building's LoD2 model from its spec and measured points: adjust, close, measure.

``build_building`` runs the whole chain: the topology from the ids (gsgeo.buildings.topology),
each face tested for planarity on its own (a face whose points deviate beyond their sigmas is
refused, naming the face and its worst point), the joint planarity adjustment
(gsgeo.buildings.adjust), the closed shell (gsgeo.buildings.solid), its checks
(gsgeo.buildings.solidcheck) and the measures (gsgeo.buildings.measures).

Frames and units: points come in the project's grid CRS, (E, N, H) in the CRS's units, with
covariances in m² (as gsgeo.crs and gsgeo.measure keep them). The computation runs in a local
frame in metres centred on the roof points; the model's vertices go back to the grid CRS.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from gsgeo.buildings.adjust import (
    Adjusted,
    Constraints,
    PlaneSet,
    adjust,
    correction_ratios,
    plane_test,
)
from gsgeo.buildings.measures import (
    Shell,
    footprint_area,
    mean_height,
    ridge_vertices,
    roof_slopes,
    roof_type,
    volume,
)
from gsgeo.buildings.solid import Surface, check_plan, corners, shell_surfaces, shell_vertices
from gsgeo.buildings.solidcheck import check_solid
from gsgeo.buildings.spec import MAX_GROUND_SIGMA_M, BuildingSpec, building_to_json
from gsgeo.buildings.topology import Topology, build_topology, face_label
from gsgeo.errors import GeometryError, InputError
from gsgeo.jsontypes import JSONObject
from gsgeo.solve.linalg import FloatArray

#: A face or the whole building is refused when its chi-square test's p-value is below this.
P_REFUSE = 0.001
#: 1-sigma (m) in E, N and H assumed for a point given without a covariance.
DEFAULT_SIGMA_M = 0.05
#: Variance floor (m²) added to a covariance too small to invert (a point typed in exactly).
VARIANCE_FLOOR_M2 = 1e-8
#: Largest |E|, |N|, |H| of a point (CRS units): beyond it no grid of the Earth.
MAX_COORDINATE = 1e9
#: Largest variance (m²) of a point's coordinate (a 1-sigma of 10 km).
MAX_VARIANCE_M2 = 1e8
#: Largest extent of a building (m).
MAX_EXTENT_M = 10_000.0
#: A right angle of ``rectangular`` may be off by this much before the constraint (degrees).
RECTANGULAR_TOLERANCE_DEG = 15.0

Points = Mapping[str, tuple[ArrayLike, ArrayLike | None]]


@dataclass
class BuildingModel:
    """A building's adjusted LoD2 model.

    ``vertices`` (V, 3): grid E, N, H (CRS units): the adjusted roof vertices first, in the
    order of ``vertex_ids`` (the roof point ids), then one ground vertex under each outline
    corner, named ``"<corner id>@ground"`` in ``vertex_ids``. ``surfaces``: the faces of the
    closed shell (rings of vertex indices, outward normals). ``covariance`` (3n, 3n, m²): the
    joint covariance of the n adjusted roof vertices (E, N, H per vertex).
    ``adjustment``: {"corrections": {id: [dE, dN, dH] m}, "faces": [{"kind", "index",
    "points", "rms" m, "chi2", "dof", "p"}], "sigma0", "chi2", "dof", "p", "iterations"}: per
    face the RMS of its vertices' corrections in the joint adjustment and its own planarity
    test (chi-square of its points against their best plane, dof = points - 3); the whole
    adjustment's chi-square, degrees of freedom, p-value and sigma0.
    ``measures``: see gsgeo.buildings.measures; heights absolute in CRS units.
    """

    id: str
    spec: BuildingSpec
    vertices: FloatArray
    vertex_ids: list[str]
    surfaces: list[Surface]
    adjustment: JSONObject
    measures: JSONObject
    warnings: list[str] = field(default_factory=list)
    covariance: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))

    def to_dict(self) -> JSONObject:
        """The model as plain JSON (lists, numbers, text)."""
        return {"id": self.id, "spec": building_to_json(self.spec),
                "vertices": self.vertices.tolist(), "vertex_ids": list(self.vertex_ids),
                "surfaces": [{"kind": s.kind, "ring": list(s.ring)} for s in self.surfaces],
                "adjustment": self.adjustment, "measures": self.measures,
                "warnings": list(self.warnings)}

    def surface_rings(self) -> list[tuple[str, FloatArray]]:
        """(kind, (k, 3) vertices in grid E, N, H) of each face, open rings, outward CCW."""
        return [(s.kind, self.vertices[list(s.ring)]) for s in self.surfaces]


def plain(value: Any) -> Any:
    """``value`` with numpy scalars and arrays turned into Python numbers and lists (what
    every JSON encoder takes)."""
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return plain(value.tolist())
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    return value


def _roof_ids(spec: BuildingSpec) -> list[str]:
    out: dict[str, None] = {}
    for ring in spec.roofs:
        for p in ring:
            out.setdefault(p)
    return list(out)


def _point(points: Points, pid: str, fld: str, warn_missing: list[str]
           ) -> tuple[FloatArray, FloatArray]:
    xyz_raw, cov_raw = points[pid]
    try:
        xyz = np.asarray(xyz_raw, dtype=np.float64).reshape(3)
    except (TypeError, ValueError):
        raise InputError(f"point {pid!r} has no usable coordinates (expected E, N, H)",
                         field=fld) from None
    if not np.all(np.isfinite(xyz)):
        raise InputError(f"point {pid!r} has no height or a coordinate that is not a number: "
                         "a roof needs 3-D points", field=fld)
    if float(np.abs(xyz).max()) > MAX_COORDINATE:
        raise InputError(f"point {pid!r} lies outside any grid ({float(np.abs(xyz).max()):.3g} "
                         f"units from the origin, more than {MAX_COORDINATE:g})", field=fld)
    if cov_raw is None:
        warn_missing.append(pid)
        return xyz, np.eye(3) * DEFAULT_SIGMA_M ** 2
    try:
        cov = np.asarray(cov_raw, dtype=np.float64).reshape(3, 3)
    except (TypeError, ValueError):
        raise InputError(f"point {pid!r}: expected a 3x3 covariance", field=fld) from None
    if not np.all(np.isfinite(cov)) or np.any(np.diag(cov) < 0):
        raise InputError(f"point {pid!r}: its covariance is not finite or has a negative "
                         "variance", field=fld)
    cov = 0.5 * (cov + cov.T)
    if float(np.abs(cov).max()) > MAX_VARIANCE_M2:
        raise InputError(f"point {pid!r}: a variance above {MAX_VARIANCE_M2:g} m² is no "
                         "measurement", field=fld)
    low = float(np.linalg.eigvalsh(cov).min())
    if low < -1e-9 * max(float(np.abs(cov).max()), 1e-300):
        raise InputError(f"point {pid!r}: its covariance is not positive semi-definite "
                         "(a correlation beyond ±1)", field=fld)
    if low < VARIANCE_FLOOR_M2:
        cov = cov + np.eye(3) * VARIANCE_FLOOR_M2
    return xyz, cov


def _measured(spec: BuildingSpec, points: Points
              ) -> tuple[list[str], FloatArray, FloatArray, list[str]]:
    """The roof ids, their coordinates (n, 3) and covariances (n, 3, 3), and the ids that had
    no covariance; InputError naming every unknown id."""
    ids = _roof_ids(spec)
    unknown = [p for p in ids if p not in points]
    if unknown:
        what = "an unknown point" if len(unknown) == 1 else "unknown points"
        raise InputError(f"the roof names {what} " + ", ".join(repr(p) for p in unknown),
                         field="roofs")
    no_cov: list[str] = []
    pts = [_point(points, p, "roofs", no_cov) for p in ids]
    return ids, np.array([p[0] for p in pts]), np.array([p[1] for p in pts]), no_cov


def footprint_en(spec: BuildingSpec, points: Points, *, unit_m: float = 1.0,
                 vertical_unit_m: float = 1.0) -> FloatArray:
    """The building's outline in plan (k, 2; grid E, N, CRS units) from the measured points,
    counter-clockwise: what gsgeo.buildings.ground.dtm_ground samples. Raises the errors of
    build_building about unknown ids and broken topology."""
    ids, xyz, cov, _ = _measured(spec, points)
    scale = np.array([unit_m, unit_m, vertical_unit_m])
    origin = xyz.mean(axis=0)
    index = {p: k for k, p in enumerate(ids)}
    topo = build_topology([tuple(index[p] for p in r) for r in spec.roofs],
                          [tuple(index[p] for p in w) for w in spec.walls],
                          (xyz - origin) * scale, cov, ids)
    return np.asarray(xyz[topo.outline, :2], dtype=np.float64)


def _resolve_ground(spec: BuildingSpec, points: Points, ground_height: float | None,
                    ground_sigma: float, warn: list[str]) -> tuple[float, float]:
    """The ground height (CRS units) and its 1-sigma (m)."""
    g = spec.ground
    if g.point_id is not None:
        if g.point_id not in points:
            raise InputError(f"the ground names an unknown point {g.point_id!r}", field="ground")
        xyz, cov = _point(points, g.point_id, "ground", warn)
        sigma = g.sigma if g.sigma is not None else math.sqrt(float(cov[2, 2]))
        return float(xyz[2]), sigma
    if ground_height is None:
        if g.height is None:
            raise InputError("the ground height is not known: sample the DTM first "
                             "(gsgeo.buildings.ground.dtm_ground)", field="ground")
        ground_height = g.height
    if not math.isfinite(ground_height) or abs(ground_height) > MAX_COORDINATE:
        raise InputError("the ground height is not a finite number within "
                         f"±{MAX_COORDINATE:g}", field="ground")
    sigma = ground_sigma if ground_sigma > 0 else (g.sigma or 0.0)
    if not 0 <= sigma <= MAX_GROUND_SIGMA_M:
        raise InputError(f"the ground's sigma must be between 0 and {MAX_GROUND_SIGMA_M:g} m, "
                         f"got {sigma:g}", field="ground")
    return float(ground_height), float(sigma)


def _face_tests(l: FloatArray, cov: FloatArray, ids: list[str],
                spec: BuildingSpec) -> list[JSONObject]:
    """Each face's own planarity test (its points against their best plane); GeometryError
    naming the face and its worst point when p < P_REFUSE."""
    out: list[JSONObject] = []
    faces = [("roof face", "roofs", i, r, False) for i, r in enumerate(spec.roofs)]
    faces += [("wall", "walls", i, w, True) for i, w in enumerate(spec.walls)]
    index = {p: k for k, p in enumerate(ids)}
    for kind, key, i, ring, vertical in faces:
        idx = [index[p] for p in ring]
        t = plane_test(l[idx], cov[idx], vertical)
        label = face_label(kind, i, ring)
        if t.p < P_REFUSE:
            raise GeometryError(
                f"{label} is not planar: its points deviate beyond their sigmas (chi-square "
                f"{t.chi2:.1f} with {t.dof} degrees of freedom, p = {t.p:.2g}); worst: point "
                f"{ring[t.worst]} is {abs(t.offset):.3f} m off the face's best plane "
                f"({t.ratio:.1f} sigma)", field=f"{key}[{i}]")
        out.append({"kind": "roof" if key == "roofs" else "wall", "index": i,
                    "points": list(ring), "chi2": t.chi2, "dof": t.dof, "p": t.p,
                    "rms": t.rms})
    return out


def _right_angles(topo: Topology, first_group_plane: int, l: FloatArray,
                  ids: list[str]) -> tuple[tuple[int, int], ...]:
    m = len(topo.groups)
    pairs: list[tuple[int, int]] = []
    for g in range(m):
        h = (g + 1) % m
        a = l[topo.groups[g][-1], :2] - l[topo.groups[g][0], :2]
        b = l[topo.groups[h][-1], :2] - l[topo.groups[h][0], :2]
        ang = math.degrees(math.acos(max(-1.0, min(1.0, float(a @ b) / float(
            np.linalg.norm(a) * np.linalg.norm(b))))))
        if abs(ang - 90.0) > RECTANGULAR_TOLERANCE_DEG:
            raise InputError(f"'rectangular' asked for, but the footprint's corner at point "
                             f"{ids[topo.groups[h][0]]} is {180 - ang:.0f} degrees, not near a "
                             "right angle", field="regularise")
        pairs.append((first_group_plane + g, first_group_plane + h))
    return tuple(pairs[:-1])  # the last right angle follows from the others around the loop


def _constraints(topo: Topology, spec: BuildingSpec, l: FloatArray,
                 ids: list[str]) -> Constraints:
    planes = [PlaneSet(tuple(r)) for r in topo.roofs]
    planes += [PlaneSet(tuple(w), vertical=True) for w in topo.walls]
    first_group = len(planes)
    planes += [PlaneSet(tuple(g), vertical=True) for g in topo.groups]
    eaves = tuple(topo.eaves) if "horizontal_eaves" in spec.regularise else ()
    right = _right_angles(topo, first_group, l, ids) if "rectangular" in spec.regularise else ()
    return Constraints(planes=tuple(planes), eaves=eaves, right_angles=right)


def _global_test(res: Adjusted, l: FloatArray, cov: FloatArray, ids: list[str]) -> None:
    if res.dof <= 0 or res.p >= P_REFUSE:
        return
    v = res.xyz - l
    ratio = correction_ratios(l, cov, res.xyz)
    worst = int(np.argmax(ratio))
    raise GeometryError(
        "the roof faces do not fit together within the points' sigmas (chi-square "
        f"{res.omega:.1f} with {res.dof} degrees of freedom, p = {res.p:.2g}): worst: point "
        f"{ids[worst]}, moved {float(np.linalg.norm(v[worst])):.3f} m "
        f"({math.sqrt(float(ratio[worst])):.1f} sigma)", field="roofs")


def build_building(spec: BuildingSpec, points: Points, ground_height: float | None = None,
                   ground_sigma: float = 0.0, *, unit_m: float = 1.0,
                   vertical_unit_m: float = 1.0) -> BuildingModel:
    """The LoD2 model of ``spec`` over ``points`` (id -> (xyz (3,) grid E, N, H; cov (3, 3) m²
    or None)).

    ``ground_height``: H of the ground (CRS vertical units) when the caller resolved it
    (Ground.height or a DTM); a ground point id is read from ``points``. ``ground_sigma``: its
    1-sigma in metres (else the spec's, else 0). ``unit_m``/``vertical_unit_m``: metres per
    CRS unit of E, N and of H.

    Raises InputError naming unknown point ids (field "roofs") and GeometryError naming a
    non-planar face and its worst point, or what breaks the solid's topology.
    """
    warnings: list[str] = []
    ids, xyz, cov, no_cov = _measured(spec, points)
    ground_crs, sigma_g = _resolve_ground(spec, points, ground_height, ground_sigma, no_cov)
    if no_cov:
        warnings.append(f"{len(no_cov)} point(s) without a covariance ({', '.join(no_cov[:5])}"
                        f"{', ...' if len(no_cov) > 5 else ''}): a 1-sigma of "
                        f"{DEFAULT_SIGMA_M:g} m in E, N and H is assumed for the adjustment, "
                        "its tests and the sigmas")
    scale = np.array([unit_m, unit_m, vertical_unit_m])
    origin = xyz.mean(axis=0)
    l = (xyz - origin) * scale
    extent = float(np.abs(l).max())
    if extent > MAX_EXTENT_M:
        raise InputError(f"the roof points spread over {2 * extent:.0f} m: a building is at "
                         f"most {MAX_EXTENT_M:g} m across", field="roofs")
    ground = (ground_crs - origin[2]) * vertical_unit_m
    if abs(ground) > MAX_EXTENT_M:
        raise GeometryError(f"the ground (H {ground_crs:.3f}) is more than {MAX_EXTENT_M:g} m "
                            "from the roof", field="ground")
    index = {p: k for k, p in enumerate(ids)}
    roof_rings = [tuple(index[p] for p in r) for r in spec.roofs]
    wall_rings = [tuple(index[p] for p in w) for w in spec.walls]
    try:
        topo = build_topology(roof_rings, wall_rings, l, cov, ids)
    except GeometryError as exc:
        raise exc if exc.field else exc.at("roofs") from None
    lowest = float(l[:, 2].min())
    if ground >= lowest:
        raise GeometryError(f"the ground (H {ground_crs:.3f}) is not below the lowest roof "
                            f"point ({ids[int(np.argmin(l[:, 2]))]}, H "
                            f"{xyz[:, 2].min():.3f})", field="ground")
    faces = _face_tests(l, cov, ids, spec)
    res = adjust(l, cov, _constraints(topo, spec, l, ids))
    _global_test(res, l, cov, ids)
    try:
        check_plan(topo, res.xyz, ids)
    except GeometryError as exc:
        raise exc.at("roofs") from None
    surfaces = shell_surfaces(topo, len(ids))
    verts = shell_vertices(res.xyz, topo, ground)
    check_solid(verts, [s.ring for s in surfaces], f"building {spec.id!r}")
    cs = corners(topo)
    shell = Shell(vertices=verts, surfaces=surfaces, n=len(ids), corner_of=cs, cov=res.cov,
                  ground_var=sigma_g ** 2)
    measures = _measures(shell, topo, res, surfaces, origin[2], ground_crs, sigma_g,
                         vertical_unit_m)
    corrections = {p: (res.xyz[k] - l[k]).tolist() for k, p in enumerate(ids)}
    v = res.xyz - l
    for face in faces:
        k = [index[p] for p in face["points"]]
        face["rms"] = float(np.sqrt(np.mean(np.sum(v[k] ** 2, axis=1))))
    adjustment: JSONObject = {"corrections": corrections, "faces": faces,
                              "sigma0": res.sigma0 if res.dof > 0 else None, "chi2": res.omega,
                              "dof": res.dof, "p": res.p, "iterations": res.iterations}
    vertices = verts / scale + origin
    return BuildingModel(id=spec.id, spec=spec, vertices=vertices,
                         vertex_ids=ids + [f"{ids[c]}@ground" for c in cs], surfaces=surfaces,
                         adjustment=plain(adjustment), measures=plain(measures),
                         warnings=warnings,
                         covariance=res.cov)


def _measures(shell: Shell, topo: Topology, res: Adjusted, surfaces: list[Surface],
              origin_h: float, ground_crs: float, sigma_g: float, vu: float) -> JSONObject:
    vol, s_vol = volume(shell)
    area, s_area = footprint_area(shell, surfaces[-1].ring)
    eaves, s_eaves = mean_height(shell, topo.eaves)
    ridge_v = ridge_vertices(res.xyz)
    ridge, s_ridge = mean_height(shell, ridge_v)
    slopes = roof_slopes(shell, topo.roofs)
    ridge_crs = ridge / vu + origin_h
    s_height = math.sqrt(s_ridge ** 2 + sigma_g ** 2)
    return {"volume": vol, "sigma_volume": s_vol, "footprint_area": area,
            "sigma_footprint_area": s_area,
            "eaves_height": eaves / vu + origin_h, "sigma_eaves_height": s_eaves / vu,
            "ridge_height": ridge_crs, "sigma_ridge_height": s_ridge / vu,
            "ground_height": ground_crs, "sigma_ground_height": sigma_g / vu,
            "measured_height": ridge_crs - ground_crs, "sigma_measured_height": s_height / vu,
            "roof_type": roof_type(topo, slopes), "roof_slopes": slopes}
