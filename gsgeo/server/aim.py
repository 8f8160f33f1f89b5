"""Routes of the aiming aids (gsgeo.service.aiming): depth hint, suggested views, matching.

POST /api/scenes/{scene}/depth, POST /api/scenes/{scene}/views, POST /api/match and POST
/api/scenes/{scene}/match (the same, its patches weighted by the scene's splats about the
click: gsgeo.aim.foreground), POST /api/snap (a click snapped onto the point feature it was
near: gsgeo.aim.snap). The scene routes read the scene's splats, so they need its
tiles on this server: 404 for an unknown scene, 409 when its tiles are served from a static
host. Matches run in the server's bounded pool of image jobs (gsgeo.server.jobs): a few at
once, a few more queued, any beyond answered 503 with Retry-After; their views' pixels are
budgeted from the images' headers before any decoding (gsgeo.aim.images).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

from fastapi import APIRouter, Request
from pydantic import BaseModel, ConfigDict, Field

from gsgeo.errors import InputError
from gsgeo.limits import DIRECTION_MAX, MAX_ORIGIN_M, SIGMA_PX_MAX, SIGMA_PX_MIN
from gsgeo.measure import Rays as RayArrays
from gsgeo.server.api import ErrorBody
from gsgeo.server.jobs import JobPool
from gsgeo.server.models import Mat16, Ray, rays_of
from gsgeo.server.scenes import SceneFolders
from gsgeo.server.textbody import TextCheckedRoute
from gsgeo.service import ConflictError, NotFoundError
from gsgeo.service.aiming import (
    MAX_VISIBILITY_POINTS,
    depth_on_ray,
    match_views,
    snap_reference,
    views_for_point,
    visibility,
)

router = APIRouter(prefix="/api", route_class=TextCheckedRoute, tags=["aiming"], responses={
    404: {"model": ErrorBody, "description": "no such scene"},
    409: {"model": ErrorBody, "description": "the scene's tiles are on a static host, not here"},
    413: {"model": ErrorBody, "description": "request body over the size limit"},
    422: {"model": ErrorBody, "description": "malformed request; message names the field"},
    503: {"model": ErrorBody, "description": "too many image matches at once; see Retry-After"},
})

Finite = Annotated[float, Field(allow_inf_nan=False)]
#: A direction's component: a length the layers can normalise (gsgeo.limits.DIRECTION_MAX).
Component = Annotated[float, Field(ge=-DIRECTION_MAX, le=DIRECTION_MAX, allow_inf_nan=False)]
Vec3 = Annotated[list[Component], Field(min_length=3, max_length=3)]
#: A position in rendered ECEF, metres: within MAX_ORIGIN_M of the Earth's centre per axis.
Coord = Annotated[float, Field(ge=-MAX_ORIGIN_M, le=MAX_ORIGIN_M, allow_inf_nan=False)]
Position = Annotated[list[Coord], Field(min_length=3, max_length=3)]
#: Window coordinates, CSS px: within ten times the largest canvas (100 000 px).
Px = Annotated[float, Field(ge=-1e6, le=1e6, allow_inf_nan=False)]
Vec2 = Annotated[list[Px], Field(min_length=2, max_length=2)]
Metres = Annotated[float, Field(ge=0, le=1e7, allow_inf_nan=False)]
Image = Annotated[str, Field(min_length=1, max_length=16_000_000,
                             description="base64 PNG or JPEG, a data: URL prefix allowed")]
SceneName = Annotated[str, Field(max_length=64, description="scene name in DATA/scenes/")]


class DepthRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    ray: Ray


class DepthAnswer(BaseModel):
    hit: bool
    depth_m: float | None = Field(description="along the ray from its origin, metres")
    point_ecef: list[float] | None = Field(description="rendered ECEF, metres")
    near_m: float | None
    far_m: float | None
    n_splats: int
    reason: str | None
    normal_ecef: list[float] | None = Field(
        None, description="unit normal of the splats' surface there, facing the ray's origin "
                          "(rendered ECEF); null where the splats are not flat or disagree")


def scene_folder(request: Request, scene: str) -> Path:
    """The folder of a scene whose tiles this server holds; NotFoundError / ConflictError."""
    folder = SceneFolders(request.app.state.config.data_dir).folder(scene)
    if folder is None or not (folder / "tileset.json").is_file():
        raise NotFoundError(f"no such scene: {scene!r}")
    if request.app.state.scene_hosts.folder(scene) is not None:
        raise ConflictError(f"the tiles of scene {scene!r} are on a static host, not on this "
                            "server: its splats cannot be read here", field="scene")
    return folder


def image_jobs(request: Request) -> JobPool:
    """The server's pool of image jobs: a match runs there, or waits its turn, or is refused
    (503) when too many wait already (gsgeo.server.jobs)."""
    pool: JobPool = request.app.state.image_jobs
    return pool


def one_ray(ray: Ray, field: str = "ray") -> RayArrays:
    """The typed ray of a request's single ray; InputError names ``ray.<member>``."""
    try:
        return rays_of([ray])
    except InputError as exc:
        raise exc.at((exc.field or "").replace("rays[0]", field, 1) or field) from None


@router.post("/scenes/{scene}/depth", response_model=DepthAnswer,
             summary="Depth hint and near/far bounds of the splats along a ray")
def depth(scene: SceneName, body: DepthRequest, request: Request) -> dict[str, Any]:
    return depth_on_ray(scene_folder(request, scene), one_ray(body.ray))


class VisibleRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    origin: Position = Field(description="the camera's centre, rendered ECEF, metres")
    points: list[Position] = Field(min_length=1, max_length=MAX_VISIBILITY_POINTS,
                                   description="points to test, rendered ECEF, metres")
    model_matrix: Mat16 | None = Field(
        None, description="the tileset's modelMatrix, 16 numbers, column-major")


class VisibleAnswer(BaseModel):
    hidden: list[bool] = Field(description="per point: the splats' surface is in front of it")
    surface_m: list[float | None] = Field(
        description="per point: distance to the splats' surface along the ray to it, metres "
                    "(null: no surface)")
    distance_m: list[float] = Field(description="per point: its distance from the origin, metres")


@router.post("/scenes/{scene}/visible", response_model=VisibleAnswer,
             summary="Whether points are hidden behind the splats, seen from a camera")
def visible(scene: SceneName, body: VisibleRequest, request: Request) -> dict[str, Any]:
    return visibility(scene_folder(request, scene), body.origin, body.points, body.model_matrix)


class CameraModel(BaseModel):
    """The viewer's camera at capture (rendered ECEF; canvas size in CSS px)."""

    model_config = ConfigDict(extra="ignore")
    position: Position
    direction: Vec3 = Field(description="unit view direction")
    up: Vec3 = Field(description="unit up, orthogonal to direction")
    fovy: Annotated[float, Field(gt=0, lt=3.14159, allow_inf_nan=False)] = Field(
        description="vertical field of view, radians")
    width: Annotated[float, Field(ge=1, le=100_000, allow_inf_nan=False)]
    height: Annotated[float, Field(ge=1, le=100_000, allow_inf_nan=False)]


class TargetView(BaseModel):
    model_config = ConfigDict(extra="forbid")
    image: Image
    origin: Vec2 = Field(default_factory=lambda: [0.0, 0.0],
                         description="window coordinates of the image's top-left corner")
    camera: CameraModel


class ReferenceView(TargetView):
    pixel: Vec2 = Field(description="window coordinates of the click")


class DepthRange(BaseModel):
    model_config = ConfigDict(extra="ignore")
    near_m: Metres
    far_m: Metres
    depth_m: Metres
    normal_ecef: Vec3 | None = Field(
        None, description="the surface normal from /depth (rendered ECEF): the patch is warped "
                          "by that plane too")


class MatchRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    reference: ReferenceView
    target: TargetView
    depth: DepthRange
    model_matrix: Mat16 | None = Field(
        None, description="the tileset's modelMatrix at the click, 16 numbers, column-major "
                          "(the scene route places the splats by it; identity when absent)")


class MatchAnswer(BaseModel):
    ok: bool
    pixel: list[float] | None = Field(description="window coordinates in the target view")
    score: float | None = Field(description="peak normalised cross-correlation, -1..1")
    second: float | None = Field(description="the best other peak along the line")
    depth_m: float | None = Field(description="along the reference ray, metres")
    reason: str | None = Field(description="why the match was declined")


@router.post("/match", response_model=MatchAnswer,
             summary="Find the reference view's click in the target view along its epipolar "
                     "segment")
async def match(body: MatchRequest, request: Request) -> dict[str, Any]:
    return await image_jobs(request).run(match_views, body.reference.model_dump(),
                                         body.target.model_dump(), body.depth.model_dump())


@router.post("/scenes/{scene}/match", response_model=MatchAnswer,
             summary="Find the reference view's click in the target view, the patches weighted "
                     "by the scene's splats about the click (its outline's background left out)")
async def scene_match(scene: SceneName, body: MatchRequest, request: Request) -> dict[str, Any]:
    folder = scene_folder(request, scene)
    return await image_jobs(request).run(match_views, body.reference.model_dump(),
                                         body.target.model_dump(), body.depth.model_dump(),
                                         folder, body.model_matrix)


class SnapRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    reference: ReferenceView


class SnapAnswer(BaseModel):
    ok: bool
    pixel: list[float] = Field(description="window coordinates: the feature when ok, else "
                                           "the click")
    moved_px: float = Field(description="how far the click moved (px)")
    isotropy: float | None = Field(description="the structure tensor's smaller eigenvalue "
                                               "over its larger one at the feature (0-1)")
    reason: str | None = Field(description="why the click was not snapped")


@router.post("/snap", response_model=SnapAnswer,
             summary="Snap a click onto the point feature (a target's centre, a corner, a "
                     "dot) within 2.5 px of it in its view, or say why not")
async def snap(body: SnapRequest, request: Request) -> dict[str, Any]:
    return await image_jobs(request).run(snap_reference, body.reference.model_dump())


class ViewsRequest(BaseModel):
    model_config = ConfigDict(extra="forbid")
    rays: Annotated[list[Ray], Field(min_length=1, max_length=1000)]
    point_ecef: Position = Field(description="provisional point, rendered ECEF, metres")
    k: Annotated[int, Field(ge=1, le=12)] = 4
    fovy: Annotated[float, Field(gt=0.01, lt=3.1, allow_inf_nan=False)] = Field(
        description="vertical field of view of the views, radians")
    width: Annotated[float, Field(ge=1, le=100_000, allow_inf_nan=False)]
    height: Annotated[float, Field(ge=1, le=100_000, allow_inf_nan=False)]
    sigma_px: Annotated[float, Field(ge=SIGMA_PX_MIN, le=SIGMA_PX_MAX, allow_inf_nan=False)] = \
        Field(1.0, description="a-priori aiming precision, pixels (the project's)")
    shape_views: bool = Field(
        False, description="views for POST /api/scenes/{scene}/match: those of a feature whose "
                           "splats are not one plane (a corner, a pole top) within 35 degrees of "
                           "the first ray, where that matcher's splat-shaped warp holds (the "
                           "plain /api/match errs there)")


class SuggestedViewModel(BaseModel):
    camera: CameraModel
    range_m: float
    azimuth_deg: float = Field(description="from the point, clockwise from north, local ENU")
    elevation_deg: float
    min_angle_deg: float = Field(description="smallest angle to the existing rays")
    predicted_sigma_m: float = Field(description="sqrt trace of the predicted covariance with "
                                                 "this view's ray added")
    occluded: bool


class ViewsAnswer(BaseModel):
    views: list[SuggestedViewModel]


@router.post("/scenes/{scene}/views", response_model=ViewsAnswer,
             summary="Suggested views of a point: most reduce its uncertainty, not occluded")
def views(scene: SceneName, body: ViewsRequest, request: Request) -> dict[str, Any]:
    folder = scene_folder(request, scene)
    return views_for_point(folder, rays_of(body.rays), body.point_ecef, body.k, body.fovy,
                           body.width, body.height, body.sigma_px, body.shape_views)
