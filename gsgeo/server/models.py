"""Request bodies of the JSON API (pydantic), in the session-JSON shapes (README, "Session JSON").

They check the JSON shape (types, lengths, sizes) so a malformed request gets 422 naming
the field; the rays then go straight into the typed core (:func:`rays_of` ->
gsgeo.measure.Rays), whose constructor is the one check of their ranges (zero direction,
origin, ifov, affine model matrix); CRS checks happen in gsgeo.service and gsgeo.crs. Each
names the field as well.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, StrictBool

from gsgeo.limits import IFOV_MAX, IFOV_MIN, MAX_ORIGIN_M, SIGMA_PX_MAX, SIGMA_PX_MIN
from gsgeo.measure import Rays as RayArrays
from gsgeo.service import PointInput

Finite = Annotated[float, Field(allow_inf_nan=False)]
Vec3 = Annotated[list[Finite], Field(min_length=3, max_length=3)]
Vec2 = Annotated[list[Finite], Field(min_length=2, max_length=2)]
Mat16 = Annotated[list[Finite], Field(min_length=16, max_length=16)]
Text = Annotated[str, Field(max_length=2000)]
Code = Annotated[str, Field(max_length=200)]
ItemId = Annotated[str, Field(min_length=1, max_length=100, pattern=r"^[^/\\\x00-\x1f\x7f]+$")]
Slug = Annotated[str, Field(pattern=r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$")]
CrsText = Annotated[str, Field(min_length=1, max_length=20000)]
RayIndex = Annotated[int, Field(ge=0, le=999)]
SigmaPx = Annotated[float, Field(ge=SIGMA_PX_MIN, le=SIGMA_PX_MAX, allow_inf_nan=False)]


class Ray(BaseModel):
    """One aim, in rendered ECEF (metres); the README's "Session JSON"."""

    model_config = ConfigDict(extra="ignore")
    origin: Vec3 = Field(description="camera centre, rendered ECEF, metres")
    direction: Vec3 = Field(description="ray direction, rendered ECEF, any non-zero length")
    ifov: Annotated[float, Field(ge=IFOV_MIN, le=IFOV_MAX, allow_inf_nan=False)] | None = Field(
        None, description="angular size of a pixel, radians")
    pixel: Vec2 | None = Field(None, description="clicked pixel (CSS px)")
    viewport: Vec2 | None = Field(None, description="canvas size (CSS px)")
    model_matrix: Mat16 | None = Field(
        None, description="tileset modelMatrix at the click, 16 numbers, column-major")
    auto: StrictBool | None = Field(
        None, description="matched automatically (true) or clicked (false; the default)")
    score: Finite | None = Field(None, description="the match score of an automatic ray")

    def provenance(self) -> dict[str, Any]:
        """The ray's ``auto`` and ``score`` as given (kept with the stored ray)."""
        return self.model_dump(include={"auto", "score"}, exclude_none=True)


Rays = Annotated[list[Ray], Field(min_length=2, max_length=1000)]


def rays_of(rays: list[Ray]) -> RayArrays:
    """The typed rays (gsgeo.measure.Rays) of validated request rays; InputError names
    ``rays[i].<member>`` for a value out of range."""
    return RayArrays.from_columns([r.origin for r in rays], [r.direction for r in rays],
                                  [r.ifov for r in rays], [r.pixel for r in rays],
                                  [r.viewport for r in rays], [r.model_matrix for r in rays],
                                  [r.auto for r in rays])


#: A position in rendered ECEF, metres: within MAX_ORIGIN_M of the Earth's centre per axis.
Coord = Annotated[float, Field(ge=-MAX_ORIGIN_M, le=MAX_ORIGIN_M, allow_inf_nan=False)]
Position = Annotated[list[Coord], Field(min_length=3, max_length=3)]


class LocateRequest(BaseModel):
    """Points the viewer shows, to be given in the project's grid (the cursor's splat)."""

    model_config = ConfigDict(extra="forbid")
    points: Annotated[list[Position], Field(min_length=1, max_length=1000)] = Field(
        description="rendered ECEF, metres")
    model_matrix: Mat16 | None = Field(
        None, description="the tileset's modelMatrix, 16 numbers, column-major (absent: identity)")


class SolveSettings(BaseModel):
    crs: CrsText | None = Field(None, description="output grid CRS, e.g. EPSG:27700")
    vertical: CrsText | None = Field(None, description="vertical CRS, e.g. EPSG:5701")
    geoid: Annotated[str, Field(max_length=200)] | None = Field(
        None, description="geoid GeoTIFF file name in DATA/geoids/")
    source_crs: CrsText = Field("EPSG:4978", description="geocentric CRS of the scene")
    sigma_px: SigmaPx = Field(1.0, description="a-priori aiming precision, pixels")


class IntersectRequest(SolveSettings):
    model_config = ConfigDict(extra="forbid")
    rays: Rays
    exclude: Annotated[list[RayIndex], Field(max_length=1000)] = Field(
        default_factory=list, description="0-based ray indices left out of the solution")
    id: ItemId = "P"
    code: Code = ""
    description: Text = ""

    def to_input(self) -> PointInput:
        """The point to measure (typed rays; ``exclude`` as its excluded rays)."""
        return PointInput(rays=rays_of(self.rays), id=self.id, code=self.code,
                          description=self.description, excluded=list(self.exclude),
                          provenance=[r.provenance() for r in self.rays])

    def settings(self) -> dict[str, str | float | None]:
        """crs, vertical, geoid, source_crs, sigma_px as a project's settings."""
        return self.model_dump(include={"crs", "vertical", "geoid", "source_crs", "sigma_px"})


class ProjectCreate(SolveSettings):
    model_config = ConfigDict(extra="forbid")
    name: Annotated[str, Field(min_length=1, max_length=200)]
    id: Slug | None = Field(None, description="URL-safe id; generated from the name when absent")
    description: Text = ""
    scene: Slug | None = Field(None, description="scene name in DATA/scenes/")


class ProjectPatch(BaseModel):
    """Any subset; changing crs, vertical, geoid, source_crs or sigma_px re-solves every point."""

    model_config = ConfigDict(extra="forbid")
    name: Annotated[str, Field(min_length=1, max_length=200)] | None = None
    description: Text | None = None
    scene: Slug | None = None
    crs: CrsText | None = None
    vertical: CrsText | None = None
    geoid: Annotated[str, Field(max_length=200)] | None = None
    source_crs: CrsText | None = None
    sigma_px: SigmaPx | None = None


class PointCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")
    id: ItemId | None = Field(None, description="point id; next free 'P<n>' when absent")
    code: Code = ""
    description: Text = ""
    rays: Rays
    excluded: Annotated[list[RayIndex], Field(max_length=1000)] = Field(default_factory=list)
    georef_version: Annotated[int, Field(ge=0, le=1_000_000)] | None = Field(
        None, description="the scene georeference version the rays were taken under "
                          "(tileset extras.gsgeo.georef.version); the current one when absent")

    def to_input(self) -> PointInput:
        """The point to store (typed rays)."""
        return PointInput(rays=rays_of(self.rays), id=self.id, code=self.code,
                          description=self.description, excluded=list(self.excluded),
                          georef_version=self.georef_version,
                          provenance=[r.provenance() for r in self.rays])


class PointPatch(BaseModel):
    """Rename (id), recode (code, description), exclude/restore rays, or replace the rays."""

    model_config = ConfigDict(extra="forbid")
    id: ItemId | None = None
    code: Code | None = None
    description: Text | None = None
    excluded: Annotated[list[RayIndex], Field(max_length=1000)] | None = Field(
        None, description="the full set of excluded ray indices")
    exclude_ray: RayIndex | None = Field(None, description="exclude one more ray (0-based)")
    restore_ray: RayIndex | None = Field(None, description="bring an excluded ray back")
    rays: Rays | None = Field(None, description="replace all rays (clears exclusions)")
    georef_version: Annotated[int, Field(ge=0, le=1_000_000)] | None = Field(
        None, description="with rays: the scene georeference version they were taken under "
                          "(the current one when absent)")


PointIds = Annotated[list[ItemId], Field(min_length=2, max_length=10000)]


class FeatureCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")
    id: ItemId | None = None
    points: PointIds = Field(description="point ids in order")
    code: Code = ""
    description: Text = ""


class FeaturePatch(BaseModel):
    model_config = ConfigDict(extra="forbid")
    id: ItemId | None = None
    points: PointIds | None = None
    code: Code | None = None
    description: Text | None = None


class CheckPointIn(BaseModel):
    model_config = ConfigDict(extra="forbid")
    id: ItemId
    x: Finite = Field(description="easting (or longitude)")
    y: Finite = Field(description="northing (or latitude)")
    z: Finite | None = Field(None, description="height; omitted when unknown")
    sigma_h: Annotated[float, Field(gt=0, le=1e4)] | None = Field(
        None, description="stated 1-sigma horizontal precision, metres")
    sigma_v: Annotated[float, Field(gt=0, le=1e4)] | None = Field(
        None, description="stated 1-sigma vertical precision, metres")
    description: Annotated[str, Field(max_length=300)] = Field(
        "", description="what and where the mark is, e.g. 'PK nail in kerb'")


class CheckPointsCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")
    crs: CrsText = Field(description="CRS the coordinates are given in, e.g. EPSG:27700")
    role: Literal["check", "control"] = "check"
    replace: bool = Field(False, description="drop the project's existing check points first")
    overwrite: Annotated[list[ItemId], Field(max_length=100000)] = Field(
        default_factory=list, description=(
            "ids of stored check points this write may replace (coordinates, CRS, role and "
            "source as given here); any other id already stored is refused with 409"))
    source: Annotated[str, Field(max_length=300)] = Field(
        "", description="where the coordinates come from (e.g. a file or layer name)")
    points: Annotated[list[CheckPointIn], Field(min_length=1, max_length=100000)]


class DistanceIn(BaseModel):
    """A known distance between two measured points (scale-only georeference)."""

    model_config = ConfigDict(extra="forbid", populate_by_name=True)
    from_: ItemId = Field(alias="from", description="first point id")
    to: ItemId = Field(description="second point id")
    distance: Annotated[float, Field(gt=0, le=1e7)] = Field(description="true distance, metres")
    sigma: Annotated[float, Field(gt=0, le=1e4)] | None = Field(
        None, description="its 1-sigma precision, metres")


class ScaleOnly(BaseModel):
    model_config = ConfigDict(extra="forbid")
    distances: Annotated[list[DistanceIn], Field(min_length=1, max_length=1000)]


class GeoreferenceRequest(BaseModel):
    """Fit (and with ``apply`` write) the scene's georeference from the project's control."""

    model_config = ConfigDict(extra="forbid")
    exclude: Annotated[list[ItemId], Field(max_length=10000)] = Field(
        default_factory=list, description="control point ids left out of the fit")
    apply: bool = Field(False, description="write the fit into the scene's tileset.json and "
                                           "re-measure every point on the scene")
    accept_outliers: bool = Field(False, description="apply although control points fail "
                                                     "the blunder test")
    scale_only: ScaleOnly | None = Field(None, description="fix only the scene's scale from "
                                                           "known distances")


FaceIds = Annotated[list[ItemId], Field(max_length=500)]
Faces = Annotated[list[FaceIds], Field(max_length=500)]
Regularise = Annotated[list[Literal["horizontal_eaves", "rectangular"]], Field(max_length=2)]
GROUND_HELP = ("the ground: a height in the project's height system (number), a measured point "
               "id (text: its H), {\"height\": H, \"sigma\": m}, {\"point\": ID, \"sigma\": m} or "
               "{\"dtm\": \"FILE.tif\"} (a GeoTIFF in DATA/dtm/, sampled under the footprint)")


class BuildingCreate(BaseModel):
    """An LoD2 building in the session-JSON form: roof faces as rings of measured point ids
    (shared ids make shared edges), a ground, free attributes (copied to CityJSON)."""

    model_config = ConfigDict(extra="forbid")
    id: ItemId | None = Field(None, description="building id; next free 'B<n>' when absent")
    roofs: Faces = Field(description="roof faces, each an ordered ring of point ids (not closed)")
    walls: Faces = Field(default_factory=list, description=(
        "vertical faces the roofs cannot express (a step between roof parts), rings of roof "
        "point ids"))
    ground: Any = Field(description=GROUND_HELP)
    attributes: dict[str, Any] = Field(default_factory=dict,
                                       description="free attributes, copied to CityJSON")
    regularise: Regularise = Field(default_factory=list,
                                   description="constraints of the adjustment")


class BuildingPatch(BaseModel):
    """Any subset of a building's fields; the rest stay as stored. It must still build."""

    model_config = ConfigDict(extra="forbid")
    id: ItemId | None = None
    roofs: Faces | None = None
    walls: Faces | None = None
    ground: Any = Field(None, description=GROUND_HELP)
    attributes: dict[str, Any] | None = None
    regularise: Regularise | None = None
