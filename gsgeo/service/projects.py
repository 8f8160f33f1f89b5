"""Projects as the API sees them: validation, measuring and re-measuring on top of a Store.

A point's rays arrive typed (gsgeo.measure.Rays, checked once); the store keeps their
session-JSON form (Rays.to_json) and the measured result, from which the point-schema record
is derived on reading (gsgeo.measure.schema.record_of), so a rename changes one copy.

Every public method is one transaction. Solving happens inside the write transaction, so a
point is never stored with a result from other settings than the ones stored with its
project, and two clients changing the same point cannot lose each other's change.
"""

from __future__ import annotations

import math
import re
import secrets
from collections.abc import Callable, Collection, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from gsgeo.crs.grid import scale_factors
from gsgeo.crs.modelmatrix import column_major
from gsgeo.errors import CRSError, GsgeoError, InputError
from gsgeo.georef.fit import georeference as fit_control
from gsgeo.georef.scale import Distance, fit_scale, origin_of
from gsgeo.jsontypes import JSON, JSONObject
from gsgeo.measure import Measurement, MeasurementFailure, Rays
from gsgeo.measure.accuracy import accuracy_report
from gsgeo.measure.batch import measure_batch_json
from gsgeo.measure.checkpoints import check_points_in_grid as points_in_grid
from gsgeo.measure.rays import SolveSettings
from gsgeo.service import audit
from gsgeo.service.buildings import BuildingService, buildings_using, rename_point
from gsgeo.service.checkpoints import FORMATS, CheckPointRow, format_from_name, read_check_points
from gsgeo.service.georeferencing import (
    SceneFrame,
    carry,
    check_stated_frame,
    frame_record,
    measured_from,
    rays_now,
    reference_from,
    restore_on_failure,
    scene_frame,
    scene_frame_and_bytes,
    scene_path,
)
from gsgeo.service.measuring import (
    check_excluded,
    find_geoid,
    json_ready,
    locate_points,
    measure,
    measured_result,
    solve_settings,
    stored_rays,
    stored_rays_many,
    with_record,
    without_cyclic_gc,
)
from gsgeo.service.points import (
    PointInput,
    check_ray_count,
    georef_version,
    point_input,
    ray_provenance,
    rays_input,
    with_provenance,
)
from gsgeo.service.validate import item_id, sigma_px, slug
from gsgeo.solve.linalg import FloatArray
from gsgeo.store.base import Store, Transaction
from gsgeo.store.records import (
    CheckPointRecord,
    ConflictError,
    FeatureRecord,
    NotFoundError,
    PointRecord,
    Project,
    require_version,
)
from gsgeo.tiles.georefhistory import apply_similarity
from gsgeo.tiles.georefhistory import undo as undo_scene

SETTINGS = ("crs", "vertical", "geoid", "source_crs", "sigma_px")
KINDS = {"line": 2, "polygon": 3}  # kind -> minimum number of points
#: What a point's frame record holds (gsgeo.service.georeferencing.frame_record).
FRAME_KEYS = frozenset({"version", "root_transform"})
MAX_FEATURE_POINTS = 10_000
#: Stored points measured at once in a re-measure: blocks large enough for the vectorised
#: batch, small enough that the store's writer has work while the next block is measured.
REMEASURE_BLOCK = 1000


def _ecef(pt: PointRecord) -> FloatArray | None:
    """A measured point's ECEF position (the scene's current frame), None when unsolved."""
    got = None if pt.result is None else pt.result.get("point_ecef")
    return None if got is None else np.asarray(got, dtype=np.float64)


def _text(value: JSON, field: str, max_len: int = 2000) -> str:
    if value is None:
        return ""
    if not isinstance(value, str):
        raise InputError("expected text", field=field)
    if len(value) > max_len:
        raise InputError(f"longer than {max_len} characters", field=field)
    return value


def validate_settings(settings: JSONObject, data_dir: Path | None) -> JSONObject:
    """Check crs / vertical / geoid / source_crs / sigma_px through gsgeo.crs; CRSError names the field."""
    from gsgeo.crs.resolve import grid_crs, source_crs

    out = dict(settings)
    for key in ("crs", "vertical", "geoid"):
        v = out.get(key)
        if v is not None and (not isinstance(v, str) or not v.strip()):
            raise InputError("expected text or null", field=key)
        out[key] = v.strip() if isinstance(v, str) else None
    src = out.get("source_crs") or "EPSG:4978"
    if not isinstance(src, str):
        raise InputError("expected text such as EPSG:4978", field="source_crs")
    out["source_crs"] = src.strip()
    out["sigma_px"] = sigma_px(out.get("sigma_px", 1.0))
    try:
        source_crs(out["source_crs"])
    except CRSError as exc:
        raise exc.within("source_crs") from None
    if out["crs"] is None and (out["vertical"] or out["geoid"]):
        raise CRSError("a vertical datum or geoid needs a grid crs as well", field="vertical")
    if out["vertical"] and out["geoid"]:
        raise CRSError("give either a vertical CRS or a geoid grid, not both", field="geoid")
    if out["crs"] is not None:
        try:
            grid_crs(out["crs"])
        except CRSError as exc:
            raise exc.within("crs") from None
        if out["vertical"]:  # the grid alone is fine: what fails now is about the vertical
            try:
                grid_crs(out["crs"], out["vertical"])
            except CRSError as exc:
                raise exc.within("vertical") from None
    find_geoid(out["geoid"], data_dir)
    return out


def intersect_request(point: PointInput, settings: JSONObject,
                      data_dir: Path | None) -> tuple[list[int], JSONObject]:
    """Check a point measured without storing it (POST /api/intersect): its excluded rays
    (errors name ``exclude``) and ``settings`` as a project's. Returns both, checked, for
    gsgeo.service.measuring.measure."""
    check_ray_count(len(point.rays))
    excluded = check_excluded(list(point.excluded), len(point.rays), "exclude")
    return excluded, validate_settings(settings, data_dir)


def intersect_point(point: PointInput, settings: JSONObject,
                    data_dir: Path | None) -> Measurement:
    """Measure one point without storing it: :func:`intersect_request` and measure."""
    excluded, checked = intersect_request(point, settings, data_dir)
    return measure(point.rays, checked, excluded, data_dir, point_id=point.id or "P",
                   code=point.code, description=point.description)


class Projects(BuildingService):
    """The project service over a :class:`~gsgeo.store.base.Store`.

    ``data_dir`` is where geoid grids (DATA/geoids/) and scenes (DATA/scenes/) live.
    """

    def __init__(self, store: Store, data_dir: str | Path | None = None) -> None:
        self.store = store
        self.data_dir = Path(data_dir) if data_dir is not None else None

    # projects -------------------------------------------------------------------------
    @staticmethod
    def _project(tx: Transaction, pid: str) -> Project:
        p = tx.get_project(pid)
        if p is None:
            raise NotFoundError(f"project '{pid}' does not exist")
        return p

    def list_projects(self) -> list[Project]:
        with self.store.transaction(write=False) as tx:
            return tx.list_projects()

    def get_project(self, pid: str) -> Project:
        with self.store.transaction(write=False) as tx:
            return self._project(tx, pid)

    def project_summary(self, pid: str) -> JSONObject:
        self.follow_scene(pid)
        with self.store.transaction(write=False) as tx:
            p = self._project(tx, pid)
            pts = tx.list_points(pid)
            return {"n_points": len(pts),
                    "n_failed": sum(1 for q in pts if q.result is None),
                    "n_lines": len(tx.list_features(pid, "line")),
                    "n_polygons": len(tx.list_features(pid, "polygon")),
                    "n_buildings": len(tx.list_buildings(pid)),
                    "n_check_points": len(tx.list_check_points(pid)),
                    "project": p}

    def create_project(self, *, name: str, id: str | None = None, description: str = "",
                       scene: str | None = None, **settings: Any) -> Project:
        name = _text(name, "name", 200).strip()
        if not name:
            raise InputError("must not be empty", field="name")
        if id is None:
            base = re.sub(r"[^A-Za-z0-9_.-]+", "-", name).strip("-.")[:40] or "project"
            if not base[0].isalnum():
                base = "p" + base
            id = f"{base}-{secrets.token_hex(3)}"
        pid = slug(id, "id")
        if scene is not None:
            scene = self._check_scene(scene)
        s = validate_settings({k: settings.get(k) for k in SETTINGS if k in settings} |
                              {"sigma_px": settings.get("sigma_px", 1.0)}, self.data_dir)
        ctx = scene_frame(self.data_dir, scene)
        p = Project(id=pid, name=name, description=_text(description, "description"),
                    scene=scene, crs=s["crs"], vertical=s["vertical"], geoid=s["geoid"],
                    source_crs=s["source_crs"], sigma_px=s["sigma_px"],
                    scene_version=None if ctx is None else ctx.version)
        with self.store.transaction() as tx:
            tx.insert_project(p)
            audit.record(tx, pid, "created", "project", None, None, audit.project_values(p))
        return p

    def _check_scene(self, scene: str) -> str:
        scene = slug(scene, "scene")
        if self.data_dir is not None:
            if not (self.data_dir / "scenes" / scene / "tileset.json").is_file():
                raise InputError(f"no scene '{scene}' in {self.data_dir / 'scenes'}",
                                 field="scene")
        return scene

    def update_project(self, pid: str, changes: JSONObject) -> Project:
        """Change name/description/scene and solving settings; a settings change re-measures
        every point from its rays in the same transaction."""
        unknown = set(changes) - {"name", "description", "scene", *SETTINGS}
        if unknown:
            raise InputError("not a project field", field=sorted(unknown)[0])
        with self.store.transaction() as tx:
            p = self._project(tx, pid)
            was = audit.project_values(p)
            if "name" in changes:
                name = _text(changes["name"], "name", 200).strip()
                if not name:
                    raise InputError("must not be empty", field="name")
                p.name = name
            if "description" in changes:
                p.description = _text(changes["description"], "description")
            moved = False
            if "scene" in changes:
                scene = None if changes["scene"] is None else self._check_scene(changes["scene"])
                moved, p.scene = scene != p.scene, scene
            if moved:
                # frames of another scene mean nothing here: the rays are taken as given in
                # the new scene's current frame, with its georeference's uncertainty
                self._remeasure_stored(tx, p, scene_frame(self.data_dir, p.scene),
                                       forget_frames=True)
            if any(k in changes for k in SETTINGS):
                new = p.settings() | {k: changes[k] for k in SETTINGS if k in changes}
                if new.get("sigma_px") is None:
                    raise InputError("must be a number of pixels, not null", field="sigma_px")
                new = validate_settings(new, self.data_dir)
                if new != p.settings():
                    for k in SETTINGS:
                        setattr(p, k, new[k])
                    p.settings_rev += 1
                    self._remeasure_all(tx, p)
            before, after = audit.changed(was, audit.project_values(p))
            if after or before:  # (a change that changes nothing is not written)
                tx.update_project(p)
                kind = "settings" if any(k in after for k in SETTINGS) else "project"
                audit.record(tx, pid, "changed", kind, None, before, after)
            return p

    def remeasure_all(self, pid: str) -> Project:
        """Re-measure every point from its rays with the current settings (one transaction),
        e.g. after a geoid grid file was replaced."""
        with self.store.transaction() as tx:
            p = self._project(tx, pid)
            was = p.settings_rev
            p.settings_rev += 1
            n = self._remeasure_stored(tx, p, scene_frame(self.data_dir, p.scene))
            tx.update_project(p)
            audit.record(tx, pid, "re-solved", "project", None, {"settings_rev": was},
                         {"settings_rev": p.settings_rev, "remeasured_points": n})
            return p

    def _remeasure_all(self, tx: Transaction, p: Project) -> None:
        self._remeasure_stored(tx, p, scene_frame(self.data_dir, p.scene))

    def _remeasure_stored(self, tx: Transaction, p: Project, ctx: SceneFrame | None, *,
                          pin: JSONObject | None = None, forget_frames: bool = False) -> int:
        """Measure every stored point of ``p`` again in the scene frame ``ctx`` and write the
        results; ``pin`` is the frame of points that record none, ``forget_frames`` drops
        every point's frame (a project moved to another scene). Returns the number of points."""
        with without_cyclic_gc():
            pts = tx.list_points(p.id, results=False)  # all measured again below
            pinned = None if pin is None else dict(pin)  # one record, shared (never mutated)
            for pt in pts:
                if forget_frames:
                    pt.frame = None
                elif pt.frame is None:
                    pt.frame = pinned
            tx.update_results(self._measure_many(pts, p, ctx))
            n = len(pts)
            # freed while the collector is still held: otherwise the objects the results are
            # made of, still alive when it resumes, start a full collection
            del pts
        self.keep_surfaces(tx, p)  # every building may have moved with its points
        p.scene_version = None if ctx is None else ctx.version
        return n

    def _measure_many(self, pts: list[PointRecord], p: Project, ctx: SceneFrame | None
                      ) -> Iterator[PointRecord]:
        """Re-measure stored points with the settings of ``p`` in the scene frame ``ctx``,
        REMEASURE_BLOCK at once (gsgeo.measure.batch: vectorised, point by point the result
        _measure_into gives); a point that fails keeps the reason. Yields each point with its new result
        for the store to write, then lets go of that result (its JSON is made and written
        one point at a time, while it is still in the caches)."""
        measured: list[JSONObject | str | None] = [None] * len(pts)
        typed: list[tuple[int, Rays]] = []
        carries: dict[tuple[float, ...], FloatArray | None] = {}  # one per distinct frame
        point_carry: list[FloatArray | None] = []
        shared: dict[tuple[object, ...], JSONObject] = {}  # equal frames as one object,
        # which the store writes once
        for pt in pts:
            pt.solved_rev = p.settings_rev
            root = () if pt.frame is None else tuple(pt.frame.get("root_transform") or ())
            if root not in carries:
                carries[root] = carry(pt.frame, ctx)
            point_carry.append(carries[root])
            if pt.frame is not None and pt.frame.keys() == FRAME_KEYS:
                pt.frame = shared.setdefault((pt.frame["version"], root), pt.frame)
        for k, rays in enumerate(stored_rays_many([q.rays for q in pts], point_carry)):
            if isinstance(rays, Rays):
                typed.append((k, rays))
            else:
                measured[k] = str(rays)
        settings: SolveSettings | str | None = None
        if typed:
            try:
                settings = solve_settings(p.settings(), self.data_dir,
                                          None if ctx is None else ctx.frame)
            except GsgeoError as exc:  # the settings fail every point alike (a missing grid)
                settings = str(exc)
        # measured a block at a time: the store writes one block (on its writer thread, see
        # gsgeo.store.sqlitebulk) while the next is measured
        done_to = 0
        for start in range(0, len(typed), REMEASURE_BLOCK):
            block = typed[start:start + REMEASURE_BLOCK]
            if isinstance(settings, str):
                for k, _ in block:
                    measured[k] = settings
                continue
            assert settings is not None  # made when there are typed rays
            try:
                results = measure_batch_json([(pts[k].id, pts[k].code, pts[k].description,
                                               rays, pts[k].excluded) for k, rays in block],
                                             settings)
                for (k, _), res in zip(block, results, strict=True):
                    measured[k] = res.error if isinstance(res, MeasurementFailure) else res
            except GsgeoError as exc:  # the settings fail every point alike
                for k, _ in block:
                    measured[k] = str(exc)
            end = typed[start + REMEASURE_BLOCK][0] if start + REMEASURE_BLOCK < len(typed) \
                else len(pts)
            yield from self._results_of(pts, measured, done_to, end)
            done_to = end
        yield from self._results_of(pts, measured, done_to, len(pts))

    @staticmethod
    def _results_of(pts: list[PointRecord], measured: list[JSONObject | str | None],
                    start: int, end: int) -> Iterator[PointRecord]:
        """Points ``start:end`` with their new results (a dict) or reasons (a text), each
        result let go of once the store has written it."""
        for k in range(start, end):
            pt, done = pts[k], measured[k]
            pt.record = None  # the point-schema record is derived when the point is read again
            if isinstance(done, dict):
                # Measurement.to_dict(), stored as is: the store writes non-finite numbers as null
                pt.result, pt.error = done, None
            else:
                pt.result, pt.error = None, done
            measured[k] = None
            yield pt
            pt.result = None  # written

    def delete_project(self, pid: str) -> None:
        with self.store.transaction() as tx:
            p = tx.get_project(pid)
            if p is None or not tx.delete_project(pid):
                raise NotFoundError(f"project '{pid}' does not exist")
            audit.record(tx, pid, "deleted", "project", None, audit.project_values(p), None)

    # points ---------------------------------------------------------------------------
    def _measure_into(self, pt: PointRecord, p: Project, strict: bool = False,
                      rays: Rays | None = None, ctx: SceneFrame | None = None) -> None:
        """Measure ``pt`` with the settings of ``p``; on failure store the reason (or raise).

        ``rays``: the point's typed rays when the caller has them; otherwise its stored rays
        are read. ``ctx``: the scene's current frame (read when not given); the rays are
        carried from the frame they were taken under into it.
        """
        ctx = ctx if ctx is not None else scene_frame(self.data_dir, p.scene)
        try:
            typed = rays if rays is not None else stored_rays(pt.rays)
            typed = rays_now(typed, pt.frame, ctx)
            m = measure(typed, p.settings(), pt.excluded, self.data_dir, point_id=pt.id,
                        code=pt.code, description=pt.description,
                        frame=None if ctx is None else ctx.frame)
            pt.result = measured_result(m)
            pt.record = with_record(pt.result)
            pt.error = None
        except GsgeoError as exc:
            if strict:
                raise
            pt.result = pt.record = None
            pt.error = str(exc)
        pt.solved_rev = p.settings_rev

    def list_points(self, pid: str) -> list[PointRecord]:
        """The project's points (each record derived from its result as it is read)."""
        self.follow_scene(pid)
        with self.store.transaction(write=False) as tx:
            self._project(tx, pid)
            return tx.list_points(pid)

    def get_point(self, pid: str, point_id: str) -> PointRecord:
        self.follow_scene(pid)
        with self.store.transaction(write=False) as tx:
            return self._point(tx, pid, point_id)

    def _point(self, tx: Transaction, pid: str, point_id: str) -> PointRecord:
        self._project(tx, pid)
        pt = tx.get_point(pid, point_id)
        if pt is None:
            raise NotFoundError(f"point '{point_id}' does not exist in project '{pid}'")
        return pt

    def add_point(self, pid: str, point: PointInput | JSONObject) -> PointRecord:
        """Measure and store a point: a PointInput (typed rays) or a mapping
        {id?, code?, description?, rays, excluded?} in the session-JSON shape.

        A point whose rays cannot be intersected is refused (GeometryError) and not stored.
        """
        new = point if isinstance(point, PointInput) else point_input(point)
        check_ray_count(len(new.rays))
        code = _text(new.code, "code", 200)
        description = _text(new.description, "description")
        excluded = check_excluded(list(new.excluded), len(new.rays))
        point_id = None if new.id is None else item_id(new.id, "id")
        # Solved before the write transaction, so that writers (one at a time, on every
        # backend) do not wait for each other's solves; measured again inside it only when
        # the project's settings or its scene's frame changed meanwhile.
        with self.store.transaction(write=False) as tx:
            p = self._project(tx, pid)
            if point_id is not None:
                self._check_new_point_id(tx, pid, point_id)
        ctx = scene_frame(self.data_dir, p.scene)
        pt = PointRecord(project_id=pid, id=point_id or "",
                         rays=with_provenance(new.rays.to_json(), new.provenance), code=code,
                         description=description, excluded=excluded,
                         frame=frame_record(ctx, new.georef_version),
                         measured_by=audit.current_actor())
        self._measure_into(pt, p, strict=True, rays=new.rays, ctx=ctx)
        check_stated_frame(ctx, new.georef_version, _ecef(pt))
        with self.store.transaction() as tx:
            now = self._project(tx, pid)
            ctx_now = scene_frame(self.data_dir, now.scene)
            if (now.scene, now.settings_rev, None if ctx_now is None else ctx_now.version) != \
                    (p.scene, p.settings_rev, None if ctx is None else ctx.version):
                pt.frame = frame_record(ctx_now, new.georef_version)
                self._measure_into(pt, now, strict=True, rays=new.rays, ctx=ctx_now)
                check_stated_frame(ctx_now, new.georef_version, _ecef(pt))
            if point_id is None:
                pt.id = self._next_id(tx.point_ids(pid))
                if pt.result is not None:  # always, once measured strictly
                    pt.result["point_id"] = pt.id
                    pt.record = with_record(pt.result)
            else:
                self._check_new_point_id(tx, pid, point_id)
            tx.insert_point(pt)
            audit.record(tx, pid, "created", "point", pt.id, None, audit.point_values(pt))
            return pt

    @staticmethod
    def _check_new_point_id(tx: Transaction, pid: str, point_id: str) -> None:
        if tx.get_point(pid, point_id) is not None:
            raise ConflictError(f"point '{point_id}' already exists in project '{pid}'",
                                field="id")

    @staticmethod
    def _next_id(existing: list[str]) -> str:
        nums = [int(m.group(1)) for s in existing if (m := re.fullmatch(r"P(\d{1,9})", s))]
        return f"P{max(nums, default=0) + 1}"

    def update_point(self, pid: str, point_id: str, changes: JSONObject,
                     if_match: Collection[int] | None = None) -> PointRecord:
        """Rename (id), recode (code, description), exclude or restore rays, or replace rays.

        ``if_match``: the versions the change is meant for (None: any); another stored
        version refuses it (PreconditionFailed), checked in the write transaction.

        changes keys: id, code, description, excluded (full list of 0-based indices),
        exclude_ray, restore_ray (one index), rays (replaces all rays; clears exclusions; with
        georef_version, the scene georeference they were taken under, else the current;
        session-JSON ray objects keep their auto / score members, typed Rays have none).
        Changing rays or exclusions re-measures; a change that leaves the point unsolvable is
        refused and nothing is written.
        """
        allowed = {"id", "code", "description", "excluded", "exclude_ray", "restore_ray", "rays",
                   "georef_version"}
        unknown = set(changes) - allowed
        if unknown:
            raise InputError("not a point field that can be changed", field=sorted(unknown)[0])
        if changes.get("georef_version") is not None and changes.get("rays") is None:
            raise InputError("applies to new rays only: give rays with it",
                             field="georef_version")
        with self.store.transaction() as tx:
            p = self._project(tx, pid)
            pt = self._point(tx, pid, point_id)
            require_version(f"point '{point_id}'", pt.version, if_match)
            was = audit.point_values(pt)
            stored = (pt.id, pt.code, pt.description, list(pt.excluded), pt.rays, pt.frame,
                      pt.measured_by)
            remeasure = False
            typed = None
            if changes.get("rays") is not None:
                typed = rays_input(changes["rays"])
                pt.measured_by = audit.current_actor()
                pt.rays = with_provenance(typed.to_json(), ray_provenance(changes["rays"]))
                pt.frame = frame_record(scene_frame(self.data_dir, p.scene),
                                        georef_version(changes.get("georef_version")))
                pt.excluded = []
                remeasure = True
            excluded = set(pt.excluded)
            if changes.get("excluded") is not None:
                excluded = set(changes["excluded"])
            if changes.get("exclude_ray") is not None:
                excluded.add(changes["exclude_ray"])
            if changes.get("restore_ray") is not None:
                i = changes["restore_ray"]
                if i not in excluded:
                    raise InputError(f"ray {i} is not excluded", field="restore_ray")
                excluded.discard(i)
            if sorted(excluded) != pt.excluded:
                field = next((k for k in ("exclude_ray", "restore_ray", "excluded")
                              if changes.get(k) is not None), "excluded")
                pt.excluded = check_excluded(list(excluded), len(pt.rays), field)
                remeasure = True
            if changes.get("code") is not None:
                pt.code = _text(changes["code"], "code", 200)
            if changes.get("description") is not None:
                pt.description = _text(changes["description"], "description")
            old_id = pt.id
            if changes.get("id") is not None:
                pt.id = item_id(changes["id"], "id")
                if pt.id != old_id and tx.get_point(pid, pt.id) is not None:
                    raise ConflictError(f"point '{pt.id}' already exists in project '{pid}'",
                                        field="id")
            if stored == (pt.id, pt.code, pt.description, pt.excluded, pt.rays, pt.frame,
                          pt.measured_by) and pt.solved_rev == p.settings_rev:
                return pt  # it changes nothing: no new version, no entry in the trail
            if remeasure or pt.solved_rev != p.settings_rev:
                self._measure_into(pt, p, strict=True, rays=typed)
                if typed is not None:
                    check_stated_frame(scene_frame(self.data_dir, p.scene),
                                       georef_version(changes.get("georef_version")), _ecef(pt))
            elif pt.result is not None:
                pt.result.update({"point_id": pt.id, "code": pt.code,
                                  "description": pt.description})
                pt.record = with_record(pt.result)
            tx.update_point(pt, old_id=old_id)
            if pt.id != old_id:
                for kind in KINDS:
                    for f in tx.list_features(pid, kind):
                        if old_id in f.point_ids:
                            f.point_ids = [pt.id if q == old_id else q for q in f.point_ids]
                            tx.update_feature(f)
                rename_point(tx, pid, old_id, pt.id)
            self.keep_surfaces(tx, p, using=pt.id)
            before, after = audit.changed(was, audit.point_values(pt))
            action = "ray excluded" if changes.get("exclude_ray") is not None else \
                "ray restored" if changes.get("restore_ray") is not None else "changed"
            audit.record(tx, pid, action, "point", old_id, before, after)
            return pt

    def delete_point(self, pid: str, point_id: str,
                     if_match: Collection[int] | None = None) -> None:
        """Delete a point; refused while a line, polygon or building uses it, or when its
        version is not in ``if_match`` (None: any)."""
        with self.store.transaction() as tx:
            pt = self._point(tx, pid, point_id)
            require_version(f"point '{point_id}'", pt.version, if_match)
            users = [f"{f.kind} '{f.id}'" for kind in KINDS for f in tx.list_features(pid, kind)
                     if point_id in f.point_ids]
            users += [f"building '{b}'" for b in buildings_using(tx, pid, point_id)]
            if users:
                raise ConflictError(f"point '{point_id}' is used by {', '.join(users)}; "
                                    "delete or change those first")
            tx.delete_point(pid, point_id)
            audit.record(tx, pid, "deleted", "point", point_id, audit.point_values(pt), None)

    def import_session(self, pid: str, doc: JSON) -> dict[str, int]:
        """Add the points, lines, polygons and buildings of a session JSON document, all or
        nothing.

        Points are solved with the project's settings (the session's own crs/sigma_px are
        ignored); an id that exists already, or a point that cannot be solved, refuses the
        whole import with a message naming it.
        """
        from gsgeo.buildings.spec import building_to_json
        from gsgeo.session import parse_session

        session = parse_session(doc)
        if not (session.points or session.lines or session.polygons or session.buildings):
            raise InputError("the session has no points, lines, polygons or buildings",
                             field="points")
        with self.store.transaction() as tx:
            p = self._project(tx, pid)
            for i, sp in enumerate(session.points):
                at = f"points[{i}]"
                point_id = item_id(sp.id, f"{at}.id")
                if len(sp.rays) < 2:
                    raise InputError("a point needs at least two rays", field=f"{at}.rays")
                if tx.get_point(pid, point_id) is not None:
                    raise ConflictError(f"point '{point_id}' already exists in project '{pid}'",
                                        field=f"{at}.id")
                typed = sp.to_rays()
                pt = PointRecord(project_id=pid, id=point_id,
                                 rays=with_provenance(typed.to_json(),
                                                      [r.provenance() for r in sp.rays]),
                                 code=sp.code, description=sp.description,
                                 frame=frame_record(scene_frame(self.data_dir, p.scene)),
                                 measured_by=audit.current_actor())
                try:
                    self._measure_into(pt, p, strict=True, rays=typed)
                except GsgeoError as exc:
                    raise exc.part_of(at, f"point '{point_id}'") from None
                tx.insert_point(pt)
            for kind, feats in (("line", session.lines), ("polygon", session.polygons)):
                for i, f in enumerate(feats):
                    at = f"{kind}s[{i}]"
                    fid = item_id(f.id, f"{at}.id")
                    try:
                        ids = self._feature_points(tx, pid, kind, f.points)
                    except InputError as exc:
                        raise exc.within(at) from None
                    if tx.get_feature(pid, kind, fid) is not None:
                        raise ConflictError(f"{kind} '{fid}' already exists", field=f"{at}.id")
                    tx.insert_feature(FeatureRecord(project_id=pid, kind=kind, id=fid,
                                                    point_ids=ids))
            for i, spec in enumerate(session.buildings):
                try:
                    self._store_building(tx, p, building_to_json(spec))
                except GsgeoError as exc:
                    raise exc.within(f"buildings[{i}]") from None
            audit.record(tx, pid, "imported", "session", None, None, {
                "points": [sp.id for sp in session.points],
                "lines": [f.id for f in session.lines],
                "polygons": [f.id for f in session.polygons],
                "buildings": [b.id for b in session.buildings]})
        counts = {"points": len(session.points), "lines": len(session.lines),
                  "polygons": len(session.polygons)}
        return counts | ({"buildings": len(session.buildings)} if session.buildings else {})

    # lines and polygons ---------------------------------------------------------------
    def _feature_points(self, tx: Transaction, pid: str, kind: str, ids: JSON) -> list[str]:
        if not isinstance(ids, list):
            raise InputError("expected a list of point ids", field="points")
        out = [item_id(v, f"points[{i}]") for i, v in enumerate(ids)]
        closed = kind == "polygon" and len(out) > 1 and out[0] == out[-1]
        if closed:
            out = out[:-1]  # closing vertex given explicitly
        if len(out) < KINDS[kind]:
            raise InputError(f"a {kind} needs at least {KINDS[kind]} points, got {len(out)}"
                             + (f" ({len(ids)} given, the last closing the ring)" if closed else ""),
                             field="points")
        if len(out) > MAX_FEATURE_POINTS:
            raise InputError(f"more than {MAX_FEATURE_POINTS} points", field="points")
        for i in range(1, len(out)):
            if out[i] == out[i - 1]:
                raise InputError(f"point '{out[i]}' repeats the one before it",
                                 field=f"points[{i}]")
        known = set(tx.point_ids(pid))
        for i, q in enumerate(out):
            if q not in known:
                raise InputError(f"point '{q}' does not exist in project '{pid}'",
                                 field=f"points[{i}]")
        return out

    def list_features(self, pid: str, kind: str) -> list[tuple[FeatureRecord, JSONObject]]:
        with self.store.transaction(write=False) as tx:
            p = self._project(tx, pid)
            feats = tx.list_features(pid, kind)
            recs = {q.id: q.record for q in tx.list_points(pid)}
        return [(f, feature_measures(f, recs, p)) for f in feats]

    def get_feature(self, pid: str, kind: str, fid: str) -> tuple[FeatureRecord, JSONObject]:
        with self.store.transaction(write=False) as tx:
            f = self._feature(tx, pid, kind, fid)
            p = self._project(tx, pid)
            recs = {q.id: q.record for q in tx.list_points(pid)}
        return f, feature_measures(f, recs, p)

    def _feature(self, tx: Transaction, pid: str, kind: str, fid: str) -> FeatureRecord:
        self._project(tx, pid)
        f = tx.get_feature(pid, kind, fid)
        if f is None:
            raise NotFoundError(f"{kind} '{fid}' does not exist in project '{pid}'")
        return f

    def add_feature(self, pid: str, kind: str, doc: JSONObject) -> FeatureRecord:
        with self.store.transaction() as tx:
            self._project(tx, pid)
            ids = self._feature_points(tx, pid, kind, doc.get("points"))
            if doc.get("id") is None:
                prefix = "L" if kind == "line" else "A"
                existing = [f.id for f in tx.list_features(pid, kind)]
                nums = [int(m.group(1)) for s in existing
                        if (m := re.fullmatch(prefix + r"(\d{1,9})", s))]
                fid = f"{prefix}{max(nums, default=0) + 1}"
            else:
                fid = item_id(doc["id"], "id")
                if tx.get_feature(pid, kind, fid) is not None:
                    raise ConflictError(f"{kind} '{fid}' already exists in project '{pid}'",
                                        field="id")
            f = FeatureRecord(project_id=pid, kind=kind, id=fid, point_ids=ids,
                              code=_text(doc.get("code"), "code", 200),
                              description=_text(doc.get("description"), "description"))
            tx.insert_feature(f)
            audit.record(tx, pid, "created", kind, fid, None, audit.feature_values(f))
            return f

    def update_feature(self, pid: str, kind: str, fid: str, changes: JSONObject,
                       if_match: Collection[int] | None = None) -> FeatureRecord:
        """Change a line's or polygon's id, points, code or description; refused when its
        version is not in ``if_match`` (None: any)."""
        unknown = set(changes) - {"id", "points", "code", "description"}
        if unknown:
            raise InputError(f"not a {kind} field that can be changed", field=sorted(unknown)[0])
        with self.store.transaction() as tx:
            f = self._feature(tx, pid, kind, fid)
            require_version(f"{kind} '{fid}'", f.version, if_match)
            was = audit.feature_values(f)
            stored = (f.id, list(f.point_ids), f.code, f.description)
            if changes.get("points") is not None:
                f.point_ids = self._feature_points(tx, pid, kind, changes["points"])
            if changes.get("code") is not None:
                f.code = _text(changes["code"], "code", 200)
            if changes.get("description") is not None:
                f.description = _text(changes["description"], "description")
            old = f.id
            if changes.get("id") is not None:
                f.id = item_id(changes["id"], "id")
                if f.id != old and tx.get_feature(pid, kind, f.id) is not None:
                    raise ConflictError(f"{kind} '{f.id}' already exists in project '{pid}'",
                                        field="id")
            if stored == (f.id, f.point_ids, f.code, f.description):
                return f  # it changes nothing: no new version, no entry in the trail
            tx.update_feature(f, old_id=old)
            before, after = audit.changed(was, audit.feature_values(f))
            audit.record(tx, pid, "changed", kind, old, before, after)
            return f

    def delete_feature(self, pid: str, kind: str, fid: str,
                       if_match: Collection[int] | None = None) -> None:
        with self.store.transaction() as tx:
            f = self._feature(tx, pid, kind, fid)
            require_version(f"{kind} '{fid}'", f.version, if_match)
            tx.delete_feature(pid, kind, fid)
            audit.record(tx, pid, "deleted", kind, fid, audit.feature_values(f), None)

    # georeference ---------------------------------------------------------------------
    def georeference_status(self, pid: str) -> JSONObject:
        """The project's scene georeference (version, history, the applied fit) and its
        control points with whether each is measured."""
        self.follow_scene(pid)
        with self.store.transaction(write=False) as tx:
            p = self._project(tx, pid)
            cps = [c for c in tx.list_check_points(pid) if c.role == "control"]
            # the control's own points only (a few), not every point of the project
            solved = {c.id for c in cps
                      if (q := tx.get_point(pid, c.id)) is not None and q.result is not None}
        ctx = scene_frame(self.data_dir, p.scene)
        history = [] if ctx is None else [
            {k: h.get(k) for k in ("version", "kind", "at", "parent", "restores",
                                   "georeferenced")}
            | {"scale": h["scale"] if "scale" in h else (h.get("summary") or {}).get("scale")}
            for h in ctx.state.history]
        current = None if ctx is None else ctx.state.record()["summary"]
        return json_ready({
            "scene": p.scene, "version": 0 if ctx is None else ctx.version,
            "georeferenced": False if ctx is None else ctx.state.georeferenced,
            "history": history,
            "control": [{"id": c.id, "x": c.x, "y": c.y, "z": c.z, "crs": c.crs,
                         "sigma_h": c.sigma_h, "sigma_v": c.sigma_v,
                         "measured": c.id in solved} for c in cps],
            "current": current})

    def _georef_solution(self, tx: Transaction, p: Project, ctx: SceneFrame | None,
                         exclude: Sequence[str],
                         distances: Sequence[Distance] | None) -> tuple[Any, JSONObject]:
        """(solution, report) of the project's control (or known distances) as stored."""
        refs = tx.list_check_points(p.id)
        wanted = {c.id for c in refs} | ({x for d in distances for x in (d.a, d.b)}
                                        if distances is not None else set())
        measured = measured_from([q for q in (tx.get_point(p.id, i) for i in sorted(wanted))
                                  if q is not None])
        if distances is not None:
            origin = origin_of(ctx.root) if ctx is not None else (
                measured.ecef.mean(axis=0) if len(measured.ids) else np.zeros(3))
            sol = fit_scale(measured, distances, origin)
            return sol, sol.report
        settings = solve_settings(p.settings(), self.data_dir)
        gsol = fit_control(measured, reference_from(refs), settings, exclude=exclude)
        return gsol, gsol.report

    def georeference(self, pid: str, *, exclude: Sequence[str] = (), apply: bool = False,
                     accept_outliers: bool = False,
                     distances: Sequence[Distance] | None = None) -> JSONObject:
        """Fit the scene's georeference from the project's measured control (or, with
        ``distances``, its scale alone) and, with ``apply``, write it into the scene's root
        transform and re-measure every point of every project on that scene, all in one
        transaction (the tileset is put back if the store cannot follow)."""
        self.follow_scene(pid)
        if not apply:
            with self.store.transaction(write=False) as tx:
                p = self._project(tx, pid)
                _, report = self._georef_solution(tx, p, scene_frame(self.data_dir, p.scene),
                                                  exclude, distances)
            return json_ready(report)

        def fit_and_write(tx: Transaction, p: Project, path: Path,
                          ctx: SceneFrame) -> JSONObject:
            sol, report = self._georef_solution(tx, p, ctx, exclude, distances)
            if report["outliers"] and not accept_outliers:
                raise InputError(
                    f"control point(s) {', '.join(report['outliers'])} fail the blunder "
                    "test; exclude them, or accept them explicitly (accept_outliers)",
                    field="accept_outliers")
            summary = dict(report) | {"exclude": list(exclude)}
            state = apply_similarity(path, sol.similarity.matrix(), kind=report["kind"],
                                     frame_covariance=sol.frame.to_json(),
                                     summary=json_ready(summary),
                                     georeferenced=report["kind"] != "scale"
                                     or ctx.state.georeferenced,
                                     expect_version=ctx.version,
                                     by=author(p.id, "georeferenced"))
            return dict(report) | {
                "applied": True,
                "scene": {"name": p.scene, "version": state.version,
                          "root_transform": column_major(state.root_transform),
                          "similarity": column_major(sol.similarity.matrix())}}

        report, n = self._change_scene(pid, fit_and_write, "georeferenced")
        return json_ready(report | {"remeasured_points": n})

    def undo_georeference(self, pid: str) -> JSONObject:
        """Restore the scene's previous georeference and re-measure every project on it."""
        def restore(_tx: Transaction, _p: Project, path: Path, _ctx: SceneFrame) -> JSONObject:
            state, sim = undo_scene(path, by=author(_p.id, "georeference undone"))
            return {"version": state.version, "georeferenced": state.georeferenced,
                    "root_transform": column_major(state.root_transform),
                    "similarity": column_major(sim)}

        out, n = self._change_scene(pid, restore, "georeference undone")
        return json_ready(out | {"remeasured_points": n})

    def _change_scene(self, pid: str, change: Callable[[Transaction, Project, Path, SceneFrame],
                                                       JSONObject],
                      action: str) -> tuple[JSONObject, int]:
        """Run ``change`` (which writes the scene's tileset.json) and re-measure every point of
        every project on the scene, in one store transaction; the tileset is put back when
        the store cannot follow. Returns what ``change`` returned and the points re-measured."""
        written: tuple[Path, bytes] | None = None
        try:
            with self.store.transaction() as tx:
                p = self._project(tx, pid)
                path = scene_path(self.data_dir, p.scene)
                if path is None:
                    raise InputError(f"project '{pid}' has no scene to georeference",
                                     field="scene")
                ctx, before = scene_frame_and_bytes(path)  # one read: the frame and its bytes
                out = change(tx, p, path, ctx)
                written = (path, before)
                now = scene_frame(self.data_dir, p.scene)
                n = self._remeasure_scene(tx, p.scene, ctx, now, pid)
                audit.record(tx, pid, action, "scene", p.scene,
                             {"version": ctx.version, "root_transform": column_major(ctx.root)},
                             {"version": None if now is None else now.version,
                              "root_transform": None if now is None else column_major(now.root),
                              "remeasured_points": n})
        except BaseException as exc:
            if written is not None:
                restore_on_failure(*written, exc)
            raise
        return out, n

    def _remeasure_scene(self, tx: Transaction, scene: str | None, before: SceneFrame,
                         ctx: SceneFrame | None, origin: str) -> int:
        """Re-measure every point of every project on ``scene`` in the scene's new frame
        ``ctx``; points without a recorded frame are pinned to the one ``before`` the change.
        The projects other than ``origin`` (whose change it is) get a "re-solved" audit
        entry."""
        pinned: JSONObject = {"version": before.version,
                              "root_transform": column_major(before.root)}
        n = 0
        for q in tx.list_projects():
            if q.scene == scene:
                m = self._remeasure_stored(tx, q, ctx, pin=pinned)
                n += m
                tx.update_project(q)  # its scene_version
                if q.id != origin:
                    audit.record(tx, q.id, "re-solved", "scene", scene,
                                 {"version": before.version},
                                 {"version": q.scene_version, "remeasured_points": m,
                                  "by_project": origin})
        return n

    def follow_scene(self, pid: str) -> bool:
        """Re-measure project ``pid`` if its scene's georeference changed without the store
        following (a session's ``gsgeo georef --apply``, a crash between writing tileset.json
        and committing the store, a hand edit): rays then follow the current frame. Cheap when
        nothing changed (a stat of tileset.json). Returns whether it re-measured."""
        with self.store.transaction(write=False) as tx:
            p = self._project(tx, pid)
        ctx = scene_frame(self.data_dir, p.scene)
        if ctx is None or p.scene_version is None or p.scene_version == ctx.version:
            return False
        with self.store.transaction() as tx:
            p = self._project(tx, pid)
            ctx = scene_frame(self.data_dir, p.scene)
            if ctx is None or p.scene_version is None or p.scene_version == ctx.version:
                return False  # another request caught up meanwhile
            was = p.scene_version
            m = self._remeasure_stored(tx, p, ctx)
            tx.update_project(p)
            self._record_catch_up(tx, p, ctx, was, m)
        return True

    @staticmethod
    def _record_catch_up(tx: Transaction, p: Project, ctx: SceneFrame, was: int,
                         remeasured: int) -> None:
        """The trail of a catch-up to the scene's version: credited to the change's author
        when the version records one (a change whose store transaction never committed,
        e.g. killed after writing tileset.json), else to nobody but the reader."""
        try:
            by = ctx.state.record().get("by")
        except InputError:
            by = None  # its side file is gone: the author is not known
        after: JSONObject = {"version": ctx.version, "remeasured_points": remeasured,
                             "caught_up_by": audit.current_actor()}
        if not isinstance(by, dict) or not isinstance(by.get("user"), str):
            audit.record(tx, p.id, "re-solved", "scene", p.scene, {"version": was},
                         after | {"reason": "the scene's georeference changed outside the "
                                            "store"})
            return
        with audit.acting_as(by["user"]):
            if by.get("project") == p.id and by.get("action") in ("georeferenced",
                                                                  "georeference undone"):
                audit.record(tx, p.id, str(by["action"]), "scene", p.scene,
                             {"version": was},
                             after | {"reason": "recorded when the next reader caught up: "
                                                "the change's own transaction did not commit"})
            else:
                audit.record(tx, p.id, "re-solved", "scene", p.scene, {"version": was},
                             after | {"by_project": by.get("project"),
                                      "reason": f"{by.get('action')} by another project"})

    # check points ---------------------------------------------------------------------
    def list_check_points(self, pid: str) -> list[CheckPointRecord]:
        with self.store.transaction(write=False) as tx:
            self._project(tx, pid)
            return tx.list_check_points(pid)

    def check_points_ecef(self, pid: str) -> list[tuple[CheckPointRecord, list[float] | None]]:
        """The project's check and control points, each with its position in ECEF (m) on the
        project's source CRS (the frame the viewer renders a georeferenced scene in), through
        the same path as control in a georeference fit; None for a point without height or
        whose CRS has no transformation here."""
        from gsgeo.georef.control import control_ecef

        with self.store.transaction(write=False) as tx:
            p = self._project(tx, pid)
            cps = tx.list_check_points(pid)
        settings = solve_settings(p.settings(), self.data_dir)
        out: list[list[float] | None] = [None] * len(cps)
        for crs in sorted({c.crs for c in cps}):
            idx = [i for i, c in enumerate(cps) if c.crs == crs and c.z is not None]
            if not idx:
                continue
            try:
                xyz = np.array([[cps[i].x, cps[i].y, cps[i].z] for i in idx], dtype=float)
                ecef = control_ecef(xyz, [crs] * len(idx),
                                    settings, [cps[i].id for i in idx])
            except GsgeoError:
                continue  # e.g. a CRS with no transformation here: those points are not drawn
            for i, e in zip(idx, ecef.tolist(), strict=True):
                out[i] = e
        return list(zip(cps, out, strict=True))

    def add_check_points(self, pid: str, rows: list[CheckPointRow], crs: str, *,
                         role: str = "check", source: str = "", replace: bool = False,
                         overwrite: Collection[str] = ()) -> int:
        """Store check points given in ``crs`` (all or nothing); ``replace`` drops the old ones.
        A repeated id is an InputError about ``points``; an id already stored is a
        ConflictError naming the ids (nothing stored) unless ``overwrite`` holds it: then the
        stored point is replaced, its role and source too, by what this write states."""
        from gsgeo.crs.resolve import parse_crs

        ids = [r.id for r in rows]
        if len(set(ids)) != len(ids):
            dup = next(i for i in ids if ids.count(i) > 1)
            raise InputError(f"duplicate id '{dup}'", field="points")
        if role not in ("check", "control"):
            raise InputError("must be 'check' or 'control'", field="role")
        try:
            parse_crs(crs)
        except CRSError as exc:
            raise exc.within("crs") from None
        allowed = {item_id(i, "overwrite") for i in overwrite}
        source = _text(source, "source", 300)
        recs = [CheckPointRecord(project_id=pid, id=r.id, x=r.x, y=r.y, z=r.z, crs=crs.strip(),
                                 role=role, source=source, sigma_h=r.sigma_h,
                                 sigma_v=r.sigma_v, description=r.description) for r in rows]
        with self.store.transaction() as tx:
            self._project(tx, pid)
            given = set(ids)
            stored = [] if replace else [c for c in tx.list_check_points(pid) if c.id in given]
            refused = [c for c in stored if c.id not in allowed]
            if refused:
                raise ConflictError(
                    f"{len(refused)} id(s) already stored: "
                    + ", ".join(f"'{c.id}' ({c.role}, {c.crs}"
                                + (f", source '{c.source}'" if c.source else "") + ")"
                                for c in refused[:20])
                    + ("; ..." if len(refused) > 20 else "")
                    + "; nothing stored. Name them in 'overwrite' to replace them, or "
                    "choose other ids", ids=[c.id for c in refused], field="points")
            # what the import drops (replace) or overwrites (asked for by id), for the trail
            gone = [audit.check_point_values(c) for c in
                    (tx.list_check_points(pid) if replace else stored)]
            replaced = tx.delete_all_check_points(pid) if replace else 0
            tx.upsert_check_points(recs)
            before: JSONObject | None = {"replaced": replaced} if replace else None
            if gone:
                before = (before or {}) | {"points": gone}
            after: JSONObject = {"ids": ids, "crs": crs.strip(), "role": role, "source": source}
            if stored:
                after["overwritten"] = [c.id for c in stored]
            audit.record(tx, pid, f"{role} points imported", "check point", None, before, after)
        return len(recs)

    def import_check_point_file(self, pid: str, data: bytes, filename: str | None, *,
                                crs: str | None = None, fmt: str | None = None,
                                role: str = "check", replace: bool = False,
                                overwrite: Collection[str] = ()) -> tuple[int, str, str]:
        """Check points from a CSV, GeoJSON or GeoPackage file (format from ``fmt`` or the
        file name; CRS from ``crs``, else the file's, else EPSG:4979 for GeoJSON).
        Returns (number stored, CRS, format)."""
        fmt = fmt or format_from_name(filename)
        if fmt is None:
            raise InputError(f"cannot tell the format of '{filename}'; give format="
                             f"{'|'.join(FORMATS)}", field="format")
        rows, file_crs = read_check_points(data, fmt, filename)
        crs = (crs or "").strip() or file_crs or ("EPSG:4979" if fmt == "geojson" else None)
        if crs is None:
            raise InputError("state the CRS the file's coordinates are in, e.g. EPSG:27700",
                             field="crs")
        n = self.add_check_points(pid, rows, crs, role=role, replace=replace,
                                  overwrite=overwrite, source=(filename or "")[:300])
        return n, crs, fmt

    def delete_check_point(self, pid: str, cid: str) -> None:
        with self.store.transaction() as tx:
            self._project(tx, pid)
            was = next((c for c in tx.list_check_points(pid) if c.id == cid), None)
            if was is None or not tx.delete_check_point(pid, cid):
                raise NotFoundError(f"check point '{cid}' does not exist in project '{pid}'")
            audit.record(tx, pid, "deleted", "check point", cid, audit.check_point_values(was),
                         None)

    def delete_all_check_points(self, pid: str) -> int:
        with self.store.transaction() as tx:
            self._project(tx, pid)
            gone = [audit.check_point_values(c) for c in tx.list_check_points(pid)]
            n = tx.delete_all_check_points(pid)
            if n:
                audit.record(tx, pid, "deleted", "check point", None,
                             {"count": n, "points": gone}, None)
            return n

    def locate(self, pid: str, points: list[list[float]],
               model_matrix: list[float] | None = None) -> JSONObject:
        """Points the viewer shows (rendered ECEF under ``model_matrix``) in the project's grid
        (gsgeo.service.measuring.locate_points), with the grid's CRS and vertical datum."""
        with self.store.transaction(write=False) as tx:
            p = self._project(tx, pid)
        return {"crs": p.crs, "vertical": p.vertical, "geoid": p.geoid,
                "points": locate_points(points, p.settings(), self.data_dir, model_matrix)}

    def accuracy(self, pid: str, role: str = "check") -> JSONObject:
        """Measured minus check point coordinates in the project's grid, matched by id."""
        self.follow_scene(pid)
        with self.store.transaction(write=False) as tx:
            p = self._project(tx, pid)
            cps = [c for c in tx.list_check_points(pid) if c.role == role]
            # the points of the check points' ids only, not every point of the project
            pts = [q for q in (tx.get_point(pid, c.id) for c in cps) if q is not None]
        if p.crs is None:
            raise InputError(f"project '{pid}' has no grid CRS; set one to compare with "
                             "check points", field="crs")
        solved = {q.id: q.record for q in pts if q.record is not None
                  and q.record.get("easting") is not None}
        matched = [c for c in cps if c.id in solved]
        hint = np.array([np.nan if solved[c.id].get("h_wgs84") is None
                         else solved[c.id]["h_wgs84"] for c in matched], dtype=float)
        grid = check_points_in_grid(matched, p, data_dir=self.data_dir, height_hint=hint)
        meas = np.array([[solved[c.id]["easting"], solved[c.id]["northing"],
                          np.nan if solved[c.id].get("height") is None else solved[c.id]["height"]]
                         for c in matched], dtype=float).reshape(-1, 3)
        rep = accuracy_report([c.id for c in matched], meas, grid)
        height_types = sorted({str(solved[c.id].get("vertical_datum") or
                                   solved[c.id].get("height_type")) for c in matched})
        rep["counts"] = {
            "check_points": len(cps), "measured_points": len(pts), "solved_points": len(solved),
            "matched": len(matched), "matched_vertical": rep["statistics"]["n_vertical"],
            "check_points_not_measured": sorted(c.id for c in cps if c.id not in solved),
            "measured_points_without_check": sorted(set(solved) - {c.id for c in cps}),
        }
        rep["crs"] = p.crs
        rep["units"] = "metres; differences are measured minus check"
        rep["heights"] = ("check points in a geographic or geocentric CRS take the measured "
                          "points' own path into the grid (heights included); heights of check "
                          "points in a projected CRS are compared as given and must be in the "
                          f"project's height system ({', '.join(height_types) or 'none'})")
        return json_ready(rep)


def author(pid: str, action: str) -> JSONObject:
    """Who makes a scene change, as the scene's history keeps it: the current actor, the
    project and the action (the trail's words)."""
    return {"user": audit.current_actor(), "project": pid, "action": action}


def check_points_in_grid(cps: list[CheckPointRecord], project: Project,
                         crs: str | None = None, data_dir: Path | None = None,
                         height_hint: FloatArray | None = None) -> FloatArray:
    """(M, 3) easting, northing, height of check points in the project's grid (or ``crs``):
    gsgeo.measure.checkpoints.check_points_in_grid with the project's settings."""
    xyz = np.array([[c.x, c.y, np.nan if c.z is None else c.z] for c in cps],
                   dtype=float).reshape(-1, 3)
    same_grid = (crs or project.crs) == project.crs  # only then is the geoid used
    settings = SolveSettings(crs=project.crs, vertical=project.vertical,
                             geoid=find_geoid(project.geoid, data_dir) if same_grid else None,
                             source_crs=project.source_crs, sigma_px=project.sigma_px)
    return points_in_grid(xyz, [c.crs for c in cps], settings, crs=crs, height_hint=height_hint)


def feature_measures(f: FeatureRecord, records: dict[str, JSONObject | None],
                     project: Project) -> JSONObject:
    """Lengths (line) or area and perimeter (polygon) with 1-sigma values, in metres and m²,
    from the points' grid coordinates and covariances (gsgeo.measure.features); an ``error``
    entry says why they cannot be computed. ``records``: point id -> its point-schema record
    (None for a point that failed)."""
    from gsgeo.crs.resolve import grid_crs
    from gsgeo.measure.features import line_measures, polygon_measures

    recs = []
    for q in f.point_ids:
        rec = records.get(q)
        if rec is None or rec.get("easting") is None:
            why = "does not exist" if q not in records else "has no grid coordinates"
            return {"error": f"point '{q}' {why}"}
        recs.append(rec)
    xyz = np.array([[r["easting"], r["northing"],
                     math.nan if r.get("height") is None else r["height"]] for r in recs])
    keys = (("cov_ee", "cov_en", "cov_eh"), ("cov_en", "cov_nn", "cov_nh"),
            ("cov_eh", "cov_nh", "cov_hh"))
    cov = np.array([[[math.nan if r.get(k) is None else r[k] for k in row] for row in keys]
                    for r in recs], dtype=float)
    try:
        g = grid_crs(project.crs, project.vertical) if project.crs else None
        units = {"unit_m": g.unit_factor if g else 1.0,
                 "vertical_unit_m": g.vertical_unit_factor if g else 1.0}
        fn = line_measures if f.kind == "line" else polygon_measures
        m = fn(xyz, cov, f.point_ids, **units)
    except GsgeoError as exc:
        return {"error": str(exc)}
    out = dict(vars(m))
    if g is not None:
        out.update(ground_measures(out, recs, project.crs or ""))
    return json_ready(out)


def ground_measures(m: JSONObject, recs: Sequence[JSONObject], crs: str) -> JSONObject:
    """The grid lengths, perimeters and areas of ``m`` reduced to the ground: divided by the
    combined scale factor (point scale factor times elevation factor, gsgeo.crs.grid.
    scale_factors) at the mean longitude, latitude and ellipsoidal height of the feature's
    points (``recs``, point-schema records), areas by its square; with the factors used.
    Empty when the points carry no WGS 84 position."""
    try:
        llh = np.array([[r["lon"], r["lat"], r["h_wgs84"]] for r in recs], dtype=float)
    except (KeyError, TypeError):
        return {}
    if not np.all(np.isfinite(llh)):
        return {}
    try:
        lon, lat, h = llh.mean(axis=0)
        f = scale_factors(lon, lat, h, crs)
    except GsgeoError:
        return {}
    csf = float(f.combined[0])
    out: JSONObject = {"scale_factor": float(f.point[0]), "elevation_factor": float(f.elevation[0]),
                       "combined_scale_factor": csf}
    for key in ("length_2d", "sigma_length_2d", "perimeter_2d", "sigma_perimeter_2d"):
        v = m.get(key)
        if isinstance(v, (int, float)):
            out[f"{key}_ground"] = v / csf
    for key in ("area_2d", "sigma_area_2d"):
        v = m.get(key)
        if isinstance(v, (int, float)):
            out[f"{key}_ground"] = v / csf**2
    return out
