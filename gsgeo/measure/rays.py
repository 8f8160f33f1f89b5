"""The typed core of a measurement's input: a point's rays and the settings it is measured with.

:class:`Rays` holds the aims of one point as arrays, in rendered ECEF (metres): the frame the
viewer draws in, the tileset's modelMatrix applied. Its constructor is the one place the
ranges of :mod:`gsgeo.limits` are checked (origin, direction, ifov, affine model matrix);
the session-JSON reader and the HTTP models only check the JSON shape and build it.
Errors name ``rays[i].<member>``; callers locate them further with ``exc.within(...)``.

:class:`SolveSettings` are the measuring settings of a session or project: output grid CRS,
vertical CRS or geoid grid, the scene's geocentric CRS and the a-priori aiming precision.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from gsgeo import limits
from gsgeo.crs.modelmatrix import rendered_to_georeferenced
from gsgeo.errors import InputError
from gsgeo.jsontypes import JSON, JSONObject
from gsgeo.measure.framecov import FrameCovariance
from gsgeo.solve.linalg import FloatArray

#: The session-JSON members of a ray, in the order they are written.
RAY_KEYS = ("origin", "direction", "ifov", "pixel", "viewport", "model_matrix")
#: Members of a stored ray that say how it was aimed (matched automatically or clicked, the
#: match score), kept with it. ``auto`` enters the measurement (Rays.auto: an auto ray shares
#: its reference click's aiming error, gsgeo.solve.sharedaim); the score is never read.
RAY_PROVENANCE_KEYS = ("auto", "score")
_IDENTITY4 = np.eye(4)


def _auto_flags(values: ArrayLike | None, n: int) -> np.ndarray | None:
    """(n,) bool auto flags, None when no ray is auto."""
    if values is None:
        return None
    a = np.array(values, dtype=bool).reshape(n)
    return a if a.any() else None


def _optional_rows(values: Sequence[ArrayLike | None] | np.ndarray | None, n: int,
                   width: int) -> np.ndarray | None:
    """(n, width) float array, NaN rows where a value is absent; None when none is given."""
    if values is None:
        return None
    if isinstance(values, np.ndarray):
        return np.asarray(values, dtype=np.float64).reshape(n, width)
    if all(v is None for v in values):
        return None
    out = np.full((n, width), np.nan)
    for i, v in enumerate(values):
        if v is not None:
            out[i] = np.asarray(v, dtype=np.float64).reshape(width)
    return out


@dataclass(frozen=True, eq=False)
class Rays:
    """N aims at one point, rendered ECEF (metres).

    origins : (N, 3) camera centres. directions : (N, 3), any length within limits.
    ifov : (N,) angular size of a pixel (radians), NaN on a ray without one; None when no
        ray has one. pixels, viewports : (N, 2) CSS pixels, NaN rows where absent, or None.
    model_matrices : (N, 4, 4) the tileset's modelMatrix at each click (NaN where the ray
        has none: identity), or None.
    auto : (N,) bool, True for a ray matched automatically to the point's first clicked ray
        (auto-aim), or None when every ray was clicked.

    Validated on construction; InputError names ``rays[i].<member>``.
    """

    origins: FloatArray
    directions: FloatArray
    ifov: FloatArray | None = None
    pixels: FloatArray | None = None
    viewports: FloatArray | None = None
    model_matrices: FloatArray | None = None
    auto: np.ndarray | None = None

    def __post_init__(self) -> None:
        o = np.asarray(self.origins, dtype=np.float64).reshape(-1, 3)
        d = np.asarray(self.directions, dtype=np.float64).reshape(-1, 3)
        n = o.shape[0]
        if d.shape[0] != n:
            raise InputError(f"{n} origins but {d.shape[0]} directions", field="rays")
        f = None if self.ifov is None else np.asarray(self.ifov, dtype=np.float64).reshape(n)
        if f is not None and np.all(np.isnan(f)):
            f = None
        px = _optional_rows(self.pixels, n, 2)
        vp = _optional_rows(self.viewports, n, 2)
        mm = None if self.model_matrices is None else \
            np.asarray(self.model_matrices, dtype=np.float64).reshape(n, 4, 4)
        for i in ([] if self._plainly_valid(o, d, f, px, vp, mm) else range(n)):
            at = f"rays[{i}]"
            problem = limits.origin_problem(o[i]) if np.all(np.isfinite(o[i])) else \
                "expected a finite number"
            if problem:
                raise InputError(problem, field=f"{at}.origin")
            problem = limits.direction_problem(d[i]) if np.all(np.isfinite(d[i])) else \
                "expected a finite number"
            if problem:
                raise InputError(problem, field=f"{at}.direction")
            if f is not None and not np.isnan(f[i]):
                limits.ifov(float(f[i]), f"{at}.ifov")
            for name, arr in (("pixel", px), ("viewport", vp)):
                if arr is not None and np.any(np.isinf(arr[i])):
                    raise InputError("expected a finite number", field=f"{at}.{name}")
            if mm is not None and not np.all(np.isnan(mm[i])):
                m = mm[i]
                if not np.all(np.isfinite(m)):
                    raise InputError("expected a finite number", field=f"{at}.model_matrix")
                if m[3, 0] != 0 or m[3, 1] != 0 or m[3, 2] != 0 or m[3, 3] == 0:
                    raise InputError("not an affine 4x4 matrix in column-major order (elements "
                                     "3, 7, 11 must be 0 and element 15 non-zero)",
                                     field=f"{at}.model_matrix")
        if mm is not None and np.all(np.isnan(mm)):
            mm = None
        auto = _auto_flags(self.auto, n)
        for name, value in (("origins", o), ("directions", d), ("ifov", f), ("pixels", px),
                            ("viewports", vp), ("model_matrices", mm), ("auto", auto)):
            if value is not None:
                value.setflags(write=False)
            object.__setattr__(self, name, value)

    @staticmethod
    def _plainly_valid(o: np.ndarray, d: np.ndarray, f: np.ndarray | None,
                       px: np.ndarray | None, vp: np.ndarray | None,
                       mm: np.ndarray | None) -> bool:
        """Every ray within gsgeo.limits, checked on whole arrays (the common case); False
        sends the caller through the per-ray checks that name the first problem."""
        if mm is not None or not (np.isfinite(o).all() and np.isfinite(d).all()):
            return False
        ro, rd = np.hypot.reduce(o, axis=1), np.hypot.reduce(d, axis=1)
        if not (np.all(ro <= limits.MAX_ORIGIN_M) and np.all(rd >= limits.DIRECTION_MIN)
                and np.all(rd <= limits.DIRECTION_MAX)):
            return False
        if f is not None:
            g = f[~np.isnan(f)]
            if not np.all((g >= limits.IFOV_MIN) & (g <= limits.IFOV_MAX)):
                return False
        return not any(a is not None and np.isinf(a).any() for a in (px, vp))

    @classmethod
    def split(cls, origins: ArrayLike, directions: ArrayLike, counts: Sequence[int],
              ifov: ArrayLike | None = None, pixels: ArrayLike | None = None,
              viewports: ArrayLike | None = None, auto: ArrayLike | None = None
              ) -> list[Rays] | None:
        """Many points' rays from stacked arrays: R = sum(counts) rows of origins, directions
        (R, 3), ifov (R,), pixels, viewports (R, 2), NaN where a ray has no such member, auto
        (R,) bool; no model matrices. Checked on the whole stack at once; None when any row is
        out of range (build those points one by one to have the problem named)."""
        # copies, made read-only whole: every point's rows are views of them
        o = np.array(origins, dtype=np.float64).reshape(-1, 3)
        d = np.array(directions, dtype=np.float64).reshape(-1, 3)
        r = o.shape[0]
        f = None if ifov is None else np.array(ifov, dtype=np.float64).reshape(r)
        px = None if pixels is None else np.array(pixels, dtype=np.float64).reshape(r, 2)
        vp = None if viewports is None else np.array(viewports, dtype=np.float64).reshape(r, 2)
        n = np.asarray(counts, dtype=np.int64)
        ends = np.cumsum(n)
        if d.shape[0] != r or (ends.size and ends[-1] != r) or \
                not cls._plainly_valid(o, d, f, px, vp, None):
            return None
        starts = ends - n
        au = None if auto is None else np.array(auto, dtype=bool).reshape(r)
        auto_given = [False] * n.size
        if au is not None:
            au.setflags(write=False)
            cum = np.concatenate([[0], np.cumsum(au)])
            auto_given = (cum[ends] > cum[starts]).tolist()
        columns: list[tuple[str, np.ndarray | None, list[bool]]] = []
        for name, arr in (("origins", o), ("directions", d), ("ifov", f), ("pixels", px),
                          ("viewports", vp)):
            if arr is not None:
                arr.setflags(write=False)
            if arr is None or name in ("origins", "directions"):
                given = [arr is not None] * n.size
            else:  # an optional member all NaN in a point is absent there (None)
                rows = ~np.isnan(arr).reshape(r, -1).all(axis=1)
                cum = np.concatenate([[0], np.cumsum(rows)])
                given = (cum[ends] > cum[starts]).tolist()
            columns.append((name, arr, given))
        out: list[Rays] = []
        for k, (a, b) in enumerate(zip(starts.tolist(), ends.tolist(), strict=True)):
            item = object.__new__(cls)
            for name, arr, given in columns:
                object.__setattr__(item, name, arr[a:b] if given[k] and arr is not None else None)
            object.__setattr__(item, "model_matrices", None)
            object.__setattr__(item, "auto", au[a:b] if auto_given[k] and au is not None else None)
            out.append(item)
        return out

    @classmethod
    def from_columns(cls, origins: Sequence[ArrayLike], directions: Sequence[ArrayLike],
                     ifov: Sequence[float | None] | None = None,
                     pixels: Sequence[ArrayLike | None] | None = None,
                     viewports: Sequence[ArrayLike | None] | None = None,
                     model_matrices: Sequence[ArrayLike | None] | None = None,
                     auto: Sequence[bool | None] | None = None) -> Rays:
        """Rays from per-ray values as JSON gives them (None where a ray has no such member;
        ``auto`` None: clicked); model matrices as 16 numbers in column-major order (3D Tiles,
        CesiumJS)."""
        n = len(origins)
        f = None
        if ifov is not None and any(v is not None for v in ifov):
            f = np.array([np.nan if v is None else float(v) for v in ifov])
        mm = None
        if model_matrices is not None and any(m is not None for m in model_matrices):
            mm = np.full((n, 4, 4), np.nan)
            for i, m16 in enumerate(model_matrices):
                if m16 is not None:
                    mm[i] = np.asarray(m16, dtype=np.float64).reshape(4, 4).T
        au = None if auto is None else np.array([bool(a) for a in auto], dtype=bool)
        return cls(np.asarray(origins, dtype=np.float64).reshape(n, 3),
                   np.asarray(directions, dtype=np.float64).reshape(n, 3), f,
                   _optional_rows(pixels, n, 2), _optional_rows(viewports, n, 2), mm, au)

    def __len__(self) -> int:
        return int(self.origins.shape[0])

    def model_matrix(self, i: int) -> FloatArray | None:
        """The (4, 4) modelMatrix of ray ``i``, None for identity (none given, or exactly the
        identity given: every ray of a georeferenced scene; so it is not stored either)."""
        if self.model_matrices is None:
            return None
        m = self.model_matrices[i]
        if np.isnan(m[0, 0]) or np.array_equal(m, _IDENTITY4):
            return None
        return m

    def angular_ifov(self) -> FloatArray | None:
        """ifov (N,) of every ray for the angular model, None for the unweighted model.

        The angular model needs ifov on every ray; ifov on some rays only is an InputError
        about the first ray without one rather than a silent fall-back.
        """
        if self.ifov is None:
            return None
        missing = np.flatnonzero(np.isnan(self.ifov))
        if missing.size:
            raise InputError(
                f"no ifov on ray(s) {', '.join(map(str, missing.tolist()))} (0-based) while the "
                "others have one; give ifov on every ray (angular model) or on none (unweighted "
                "model)", field=f"rays[{int(missing[0])}].ifov")
        return self.ifov

    def mapped(self, similarity: ArrayLike) -> Rays:
        """These rays carried by a similarity (4, 4; ECEF -> ECEF, y = s R x + t), e.g. into a
        scene's new georeference: each ray's modelMatrix is undone first (georeferenced
        ECEF), origins map as points, directions by R (unit length); ifov, pixels and
        viewports stay (angles are kept). The result has no model matrices."""
        s = np.asarray(similarity, dtype=np.float64).reshape(4, 4)
        o, d, _ = rendered_to_georeferenced(self.origins, self.directions,
                                            [self.model_matrix(i) for i in range(len(self))])
        lin = s[:3, :3]
        d2 = d @ lin.T
        d2 /= np.linalg.norm(d2, axis=1, keepdims=True)
        o2 = o @ lin.T + s[:3, 3]
        split = Rays.split(o2, d2, [len(self)], self.ifov, self.pixels, self.viewports, self.auto)
        # out of range after the carry: the constructor names the ray
        return split[0] if split else Rays(o2, d2, self.ifov, self.pixels, self.viewports,
                                           auto=self.auto)

    def to_json(self) -> list[JSONObject]:
        """The session-JSON ray objects (README, "Session JSON"), members only where given."""
        out: list[JSONObject] = []
        for i in range(len(self)):
            ray: JSONObject = {"origin": self.origins[i].tolist(),
                                   "direction": self.directions[i].tolist()}
            if self.ifov is not None and not np.isnan(self.ifov[i]):
                ray["ifov"] = float(self.ifov[i])
            for key, arr in (("pixel", self.pixels), ("viewport", self.viewports)):
                if arr is not None and not np.all(np.isnan(arr[i])):
                    ray[key] = arr[i].tolist()
            m = self.model_matrix(i)
            if m is not None:
                ray["model_matrix"] = m.T.reshape(-1).tolist()
            out.append(ray)
        return out


@dataclass(frozen=True)
class SolveSettings:
    """How a point is measured: grid ``crs`` (None: ECEF and WGS 84 only), ``vertical`` CRS
    or ``geoid`` grid file (not both), ``source_crs`` (the scene's geocentric CRS) and
    ``sigma_px`` (a-priori aiming precision, pixels). Build with :meth:`parse` to check it."""

    crs: str | None = None
    vertical: str | None = None
    geoid: str | Path | None = None
    source_crs: str = "EPSG:4978"
    sigma_px: float = 1.0
    frame: FrameCovariance | None = None

    @classmethod
    def parse(cls, *, crs: str | None = None, vertical: str | None = None,
              geoid: str | Path | None = None, source_crs: str | None = None,
              sigma_px: JSON = 1.0, frame: FrameCovariance | None = None) -> SolveSettings:
        """Settings with sigma_px within gsgeo.limits and an empty source_crs meaning
        EPSG:4978; InputError names the field. The CRSs are parsed where they are used."""
        return cls(crs=crs or None, vertical=vertical or None, geoid=geoid or None,
                   source_crs=source_crs or "EPSG:4978",
                   sigma_px=limits.sigma_px(sigma_px, "sigma_px"), frame=frame)
