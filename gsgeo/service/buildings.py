"""LoD2 buildings of a project (gsgeo.buildings) over the store, and the same for a session.

The store keeps what the user gave (the session-JSON form: roof faces as rings of point ids,
the ground, attributes); the model (adjusted vertices, walls, measures) is built from the
points' current results each time it is read, as the lengths of lines are. So a building
follows every change of its points (new rays, an excluded ray, another CRS, a re-measure
after the scene's georeference changed) without being recomputed in each of those places.

Frames: vertices in the project's grid CRS (E, N, H in its units, its height system);
``vertices_ecef`` in ECEF metres of the project's source CRS (as a point's ``point_ecef``),
through the points' own CRS path backwards (gsgeo.georef.control.grid_to_ecef).

A ground given as a DTM is a GeoTIFF file in DATA/dtm/ named by its file name for a stored
building (a server never reads a path a request names); a session names it relative to the
session file.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import orjson

from gsgeo.buildings.model import BuildingModel, build_building
from gsgeo.buildings.spec import BuildingSpec, building_to_json, parse_building, point_ids
from gsgeo.errors import CRSError, GsgeoError, InputError
from gsgeo.export.tables import building_table
from gsgeo.georef.control import grid_to_ecef
from gsgeo.jsontypes import JSON, JSONObject
from gsgeo.service import audit
from gsgeo.service.measuring import json_ready, solve_settings
from gsgeo.service.validate import item_id
from gsgeo.store.base import Store, Transaction
from gsgeo.store.records import (
    BuildingRecord,
    ConflictError,
    NotFoundError,
    Project,
    require_version,
)
from gsgeo.store.surfaces import BuildingSurface

#: Directory of DTM GeoTIFFs inside the data directory.
DTM_DIR = "dtm"
#: Most distinct points one building may use: its adjustment is dense in them, so its cost
#: grows with their cube (about 2 s of CPU for 200 points on a 2-core machine, and the model
#: is rebuilt on every read); an LoD2 building has a few dozen.
MAX_BUILDING_POINTS = 200
#: Fields of a building that PATCH may change.
BUILDING_FIELDS = ("id", "roofs", "walls", "ground", "attributes", "regularise")

#: Resolves a DTM named in a building's ground to the file to read.
DtmResolver = Callable[[str], Path]

_COV_KEYS = (("cov_ee", "cov_en", "cov_eh"), ("cov_en", "cov_nn", "cov_nh"),
             ("cov_eh", "cov_nh", "cov_hh"))


def dtm_in_data_dir(data_dir: Path | None) -> DtmResolver:
    """The resolver of a stored building's DTM: a file directly in DATA/dtm/ (never another
    path); InputError about ``ground.dtm`` otherwise."""

    def resolve(name: str) -> Path:
        if data_dir is None:
            raise InputError("no data directory to look up DTMs in", field="ground.dtm")
        ddir = (Path(data_dir) / DTM_DIR).resolve()
        path = (ddir / name).resolve()
        if path.parent != ddir or not path.is_file():
            raise InputError(f"no DTM '{name}' in {ddir}: a stored building's DTM is a GeoTIFF "
                             "file there, named by its file name", field="ground.dtm")
        return path

    return resolve


def dtm_beside(session_file: Path) -> DtmResolver:
    """The resolver of a session's DTM: the path as given, relative to the session file."""

    def resolve(name: str) -> Path:
        path = Path(name)
        path = path if path.is_absolute() else session_file.parent / path
        if not path.is_file():
            raise InputError(f"no DTM file {path}", field="ground.dtm")
        return path

    return resolve


def point_inputs(records: Mapping[str, JSONObject | None],
                 ids: Sequence[str]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Grid position (E, N, H) and covariance (3, 3, m^2) of each point id from its
    point-schema record; InputError naming a point that does not exist or has no grid
    coordinates (it could not be solved)."""
    out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for q in dict.fromkeys(ids):
        if q not in records:
            raise InputError(f"point '{q}' does not exist", field="roofs")
        rec = records[q]
        if rec is None:
            raise InputError(f"point '{q}' could not be solved", field="roofs")
        xyz = [rec.get("easting"), rec.get("northing"), rec.get("height")]
        if any(v is None for v in xyz):
            raise InputError(f"point '{q}' has no grid coordinates (E, N, H): give the "
                             "project a grid CRS", field="roofs")
        cov = np.array([[math.nan if rec.get(k) is None else rec[k] for k in row]
                        for row in _COV_KEYS], dtype=float)
        out[q] = (np.array(xyz, dtype=float), cov)
    return out


def footprint(spec: BuildingSpec, pts: Mapping[str, tuple[np.ndarray, np.ndarray]]
              ) -> np.ndarray:
    """(k, 2) E, N of the outline of the roof faces seen from above, in order: the union of
    the faces' plan polygons (shared edges share their points), its convex hull if the parts
    do not join."""
    import shapely

    faces = [shapely.Polygon([pts[q][0][:2] for q in face]) for face in spec.roofs]
    union = shapely.union_all([f if f.is_valid else f.buffer(0) for f in faces])
    if union.geom_type != "Polygon" or union.area <= 0:
        union = shapely.MultiPoint([p[0][:2] for p in pts.values()]).convex_hull
    if union.geom_type != "Polygon" or union.area <= 0:
        raise InputError("the roof faces cover no area seen from above: no footprint to "
                         "sample the DTM under", field="roofs")
    return np.asarray(union.exterior.coords, dtype=float)[:-1]


def building_model(spec: BuildingSpec, records: Mapping[str, JSONObject | None], crs: str,
                   vertical: str | None, dtm: DtmResolver) -> BuildingModel:
    """The model of ``spec`` from the points' records in the grid ``crs`` (+ ``vertical``):
    its ground resolved (a height, a point's H, or the DTM under the roof points)."""
    from gsgeo.crs.resolve import grid_crs

    g = grid_crs(crs, vertical)
    pts = point_inputs(records, point_ids(spec))
    height, sigma = spec.ground.height, spec.ground.sigma or 0.0
    if spec.ground.dtm is not None:
        path = dtm(spec.ground.dtm)  # refused before anything is read
        from gsgeo.buildings.ground import dtm_ground

        height, sigma = dtm_ground(path, footprint(spec, pts), g.horizontal)
    return build_building(spec, pts, ground_height=height, ground_sigma=sigma,
                          unit_m=g.unit_factor, vertical_unit_m=g.vertical_unit_factor)


def reference_crs(crs: str, vertical: str | None) -> Any:
    """The pyproj CRS a CityJSON file states: the grid, compound with its vertical CRS."""
    from pyproj.crs import CompoundCRS

    from gsgeo.crs.resolve import grid_crs

    g = grid_crs(crs, vertical)
    if g.vertical is None:
        return g.horizontal
    return CompoundCRS(f"{g.horizontal.name} + {g.vertical.name}", [g.horizontal, g.vertical])


@dataclass
class BuildingResult:
    """A stored building and its model now, or why there is none (``error``)."""

    record: BuildingRecord
    model: BuildingModel | None
    error: str | None = None


def building_surfaces(model: BuildingModel) -> list[BuildingSurface]:
    """The surfaces of a built building as a store keeps them for GIS: the rows of the
    exports' buildings layer (gsgeo.export.tables.building_table, the columns of
    gsgeo.pointschema.BUILDING_TYPES) with their rings (E, N, H in the grid CRS)."""
    got = building_table([model])
    if got is None:
        return []
    table, rings = got
    out = []
    for i, ring in enumerate(rings):
        values = json_ready({k: col[i] for k, col in table.columns.items()})
        if not isinstance(values, dict):
            continue  # (json_ready keeps a dict a dict)
        out.append(BuildingSurface(str(values["building_id"]), i, values,
                                   [(float(x), float(y), float(z)) for x, y, z in ring]))
    return out


def building_json(r: BuildingResult, project: Project, data_dir: Path | None) -> JSONObject:
    """The API's answer: BuildingModel.to_dict() plus ``vertices_ecef`` (ECEF metres of the
    project's source CRS, in the order of ``vertices``), ``error`` (None when built) and the
    record's times and version. A building that cannot be built now has its ``spec`` and
    ``error``."""
    out: JSONObject
    if r.model is None:
        out = {"id": r.record.id, "spec": r.record.spec, "error": r.error}
    else:
        out = dict(r.model.to_dict())
        try:
            ecef = grid_to_ecef(r.model.vertices, solve_settings(project.settings(), data_dir))
            out["vertices_ecef"] = ecef.tolist()
        except GsgeoError as exc:
            out["vertices_ecef"] = None
            out["warnings"] = [*out.get("warnings", []), f"no ECEF vertices: {exc}"]
        out["error"] = None
    out["created_at"], out["updated_at"] = r.record.created_at, r.record.updated_at
    out["version"] = r.record.version
    return json_ready(out)


def spec_point_ids(spec: JSONObject) -> list[str]:
    """Every point id a stored building (its session-JSON form) uses, each once."""
    return point_ids(parse_building(spec))


def buildings_using(tx: Transaction, pid: str, point_id: str) -> list[str]:
    """The ids of the project's buildings whose roofs, walls or ground use ``point_id``."""
    return [b.id for b in tx.list_buildings(pid) if point_id in spec_point_ids(b.spec)]


def rename_point(tx: Transaction, pid: str, old: str, new: str) -> None:
    """A point renamed: every building naming it names the new id."""
    for b in tx.list_buildings(pid):
        spec = parse_building(b.spec)
        if old not in point_ids(spec):
            continue

        def ring(ids: tuple[str, ...]) -> tuple[str, ...]:
            return tuple(new if q == old else q for q in ids)

        ground = spec.ground
        if ground.point_id == old:
            ground = replace(ground, point_id=new)
        b.spec = json_ready(building_to_json(replace(
            spec, roofs=tuple(map(ring, spec.roofs)), walls=tuple(map(ring, spec.walls)),
            ground=ground)))
        tx.update_building(b)


def next_building_id(existing: Sequence[str]) -> str:
    nums = [int(m.group(1)) for s in existing if (m := re.fullmatch(r"B(\d{1,9})", s))]
    return f"B{max(nums, default=0) + 1}"


class BuildingService:
    """The building methods of gsgeo.service.projects.Projects (one transaction each)."""

    store: Store
    data_dir: Path | None

    def follow_scene(self, pid: str) -> bool:
        """Catch up with the scene's georeference before reading (Projects' own does)."""
        return False

    def _building_project(self, tx: Transaction, pid: str) -> Project:
        p = tx.get_project(pid)
        if p is None:
            raise NotFoundError(f"project '{pid}' does not exist")
        return p

    def built_in(self, tx: Transaction, p: Project, b: BuildingRecord,
               strict: bool = False) -> BuildingResult:
        """The model of a stored building from the points now; with ``strict`` an error
        is raised (a new or changed building is refused), else kept in the result."""
        try:
            if p.crs is None:
                raise CRSError(f"project '{p.id}' has no grid CRS; a building needs one",
                               field="crs")
            spec = parse_building(b.spec)
            stored = [tx.get_point(p.id, q) for q in point_ids(spec)]
            records = {pt.id: pt.record for pt in stored if pt is not None}
            model = building_model(spec, records, p.crs, p.vertical,
                                   dtm_in_data_dir(self.data_dir))
        except (GsgeoError, ValueError, ArithmeticError) as exc:
            # ValueError / ArithmeticError: numbers the maths cannot take (numpy's LinAlgError
            # among them), said as such rather than answered as an internal error
            if strict:
                if isinstance(exc, GsgeoError):
                    raise
                raise InputError(f"building '{b.id}' cannot be built: {exc}") from None
            return BuildingResult(b, None, str(exc))
        return BuildingResult(b, model)

    def keep_surfaces(self, tx: Transaction, p: Project, only: BuildingResult | None = None,
                      *, using: str | None = None) -> None:
        """Rewrite the surfaces the store keeps for GIS (gsgeo.store.base.Transaction.
        set_building_surfaces) of project ``p``'s buildings as they build now, inside ``tx``:
        ``only`` one just built, or those that use point ``using``, or all of them. Called in
        the transaction of every change that can move a building; nothing where the store
        keeps no surfaces."""
        if not tx.keeps_building_surfaces():
            return
        if only is not None:
            results = [only]
        else:
            results = [self.built_in(tx, p, b) for b in tx.list_buildings(p.id)
                       if using is None or using in spec_point_ids(b.spec)]
        for r in results:
            tx.set_building_surfaces(p.id, r.record.id,
                                     [] if r.model is None else building_surfaces(r.model))

    def keep_missing_surfaces(self) -> int:
        """Write the kept surfaces of every building that has none (stored by a gsgeo that
        kept none; one that cannot be built is tried again); returns how many buildings were
        looked at. Nothing where the store keeps no surfaces."""
        with self.store.transaction(write=False) as tx:
            missing = tx.buildings_without_surfaces() if tx.keeps_building_surfaces() else []
        if not missing:
            return 0
        with self.store.transaction() as tx:
            for pid in dict.fromkeys(q for q, _ in missing):
                p = tx.get_project(pid)
                wanted = {b for q, b in missing if q == pid}
                for b in [] if p is None else tx.list_buildings(pid):
                    if p is not None and b.id in wanted:
                        self.keep_surfaces(tx, p, self.built_in(tx, p, b))
        return len(missing)

    def building_results(self, pid: str) -> tuple[Project, list[BuildingResult]]:
        """The project and each of its buildings with its model now (or its error)."""
        self.follow_scene(pid)
        with self.store.transaction(write=False) as tx:
            p = self._building_project(tx, pid)
            return p, [self.built_in(tx, p, b) for b in tx.list_buildings(pid)]

    def list_building_records(self, pid: str) -> list[BuildingRecord]:
        """The project's buildings as stored (their specs), in creation order."""
        with self.store.transaction(write=False) as tx:
            self._building_project(tx, pid)
            return tx.list_buildings(pid)

    def list_buildings(self, pid: str) -> list[JSONObject]:
        p, results = self.building_results(pid)
        return [building_json(r, p, self.data_dir) for r in results]

    def get_building(self, pid: str, bid: str) -> JSONObject:
        self.follow_scene(pid)
        with self.store.transaction(write=False) as tx:
            p = self._building_project(tx, pid)
            r = self.built_in(tx, p, self._stored_building(tx, pid, bid))
        return building_json(r, p, self.data_dir)

    def _stored_building(self, tx: Transaction, pid: str, bid: str) -> BuildingRecord:
        b = tx.get_building(pid, bid)
        if b is None:
            raise NotFoundError(f"building '{bid}' does not exist in project '{pid}'")
        return b

    def _checked_spec(self, tx: Transaction, pid: str, doc: JSON) -> JSONObject:
        """The session-JSON form of a building, parsed (gsgeo.buildings.spec) and with every
        point it names measured in the project; InputError naming the field otherwise."""
        spec = parse_building(doc, "")
        item_id(spec.id, "id")
        if len(point_ids(spec)) > MAX_BUILDING_POINTS:
            raise InputError(f"uses {len(point_ids(spec))} points; a building may use at most "
                             f"{MAX_BUILDING_POINTS}", field="roofs")
        known = set(tx.point_ids(pid))
        for i, face in enumerate(spec.roofs):
            for j, q in enumerate(face):
                if q not in known:
                    raise InputError(f"point '{q}' does not exist in project '{pid}'",
                                     field=f"roofs[{i}][{j}]")
        if spec.ground.point_id is not None and spec.ground.point_id not in known:
            raise InputError(f"point '{spec.ground.point_id}' does not exist in project "
                             f"'{pid}'", field="ground")
        out = building_to_json(spec)
        try:  # what the store and every answer will write: UTF-8, 64-bit numbers, bounded depth
            orjson.dumps(out)
        except orjson.JSONEncodeError as exc:
            raise InputError(f"cannot be kept as JSON: {exc} (text must be valid Unicode, "
                             "integers within 64 bits)", field="attributes") from None
        return json_ready(out)

    def add_building(self, pid: str, doc: JSON) -> JSONObject:
        """Check, build and store a building given in its session-JSON form (``id``
        optional: the next free 'B<n>'); one that cannot be built is refused."""
        if not isinstance(doc, dict):
            raise InputError("expected a building object with id, roofs and ground")
        with self.store.transaction() as tx:
            p = self._building_project(tx, pid)
            r = self._store_building(tx, p, doc)
            audit.record(tx, pid, "created", "building", r.record.id, None,
                         audit.building_values(r.record))
        return building_json(r, p, self.data_dir)

    def _store_building(self, tx: Transaction, p: Project, doc: JSONObject) -> BuildingResult:
        """Check, build and insert one building of project ``p`` inside ``tx``."""
        if doc.get("id") is None:
            doc = dict(doc) | {"id": next_building_id([b.id for b in tx.list_buildings(p.id)])}
        spec = self._checked_spec(tx, p.id, doc)
        if tx.get_building(p.id, spec["id"]) is not None:
            raise ConflictError(f"building '{spec['id']}' already exists in project "
                                f"'{p.id}'", field="id")
        b = BuildingRecord(project_id=p.id, id=spec["id"], spec=spec)
        r = self.built_in(tx, p, b, strict=True)
        tx.insert_building(b)
        self.keep_surfaces(tx, p, r)
        return r

    def update_building(self, pid: str, bid: str, changes: JSONObject,
                        if_match: Collection[int] | None = None) -> JSONObject:
        """Change any of id, roofs, walls, ground, attributes, regularise (the rest as stored);
        the changed building must build, else nothing is written. Refused when its version
        is not in ``if_match`` (None: any)."""
        unknown = set(changes) - set(BUILDING_FIELDS)
        if unknown:
            raise InputError("not a building field that can be changed",
                             field=sorted(unknown)[0])
        with self.store.transaction() as tx:
            p = self._building_project(tx, pid)
            b = self._stored_building(tx, pid, bid)
            require_version(f"building '{bid}'", b.version, if_match)
            old = b.id
            was = audit.building_values(b)
            b.spec = self._checked_spec(tx, pid, dict(b.spec) | dict(changes))
            b.id = b.spec["id"]
            if b.spec == was:  # it changes nothing: no new version, no entry in the trail
                return building_json(self.built_in(tx, p, b), p, self.data_dir)
            if b.id != old and tx.get_building(pid, b.id) is not None:
                raise ConflictError(f"building '{b.id}' already exists in project '{pid}'",
                                    field="id")
            r = self.built_in(tx, p, b, strict=True)
            tx.update_building(b, old_id=old)
            self.keep_surfaces(tx, p, r)
            before, after = audit.changed(was, audit.building_values(b))
            audit.record(tx, pid, "changed", "building", old, before, after)
        return building_json(r, p, self.data_dir)

    def delete_building(self, pid: str, bid: str,
                        if_match: Collection[int] | None = None) -> None:
        with self.store.transaction() as tx:
            self._building_project(tx, pid)
            b = self._stored_building(tx, pid, bid)
            require_version(f"building '{bid}'", b.version, if_match)
            tx.delete_building(pid, bid)
            audit.record(tx, pid, "deleted", "building", bid, audit.building_values(b), None)
