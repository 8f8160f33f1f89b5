"""CityJSON 2.0 documents of LoD2 buildings.

One ``Building`` city object per model, with one geometry: a ``Solid`` at ``lod`` "2.2" whose
single shell holds the roof, wall and ground faces with their semantic surfaces
(``RoofSurface`` / ``WallSurface`` / ``GroundSurface``). Vertices are quantised to integers
with ``transform.scale`` 0.001 (a millimetre in a metric CRS: vertices keep the CRS's units)
and ``transform.translate`` the lower corner of all vertices. ``metadata.referenceSystem`` is
the project CRS as an OGC URI. Attributes: the measures (heights in the CRS's vertical units,
volume m³, footprint area m², sigmas 1-sigma) and the user's attributes.

Every shell is checked (gsgeo.buildings.solidcheck) after quantisation and before anything is
returned: an invalid solid is never written.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import orjson
import pyproj

from gsgeo.buildings.model import BuildingModel
from gsgeo.buildings.solidcheck import check_solid
from gsgeo.errors import GeometryError, InputError
from gsgeo.jsontypes import JSONObject

VERSION = "2.0"
LOD = "2.2"
#: Quantisation step, CRS units (a millimetre in a metric CRS).
SCALE = 0.001
#: After quantisation a face may be off its plane by about a scale step.
QUANTISED_PLANARITY = 2.0 * SCALE
OGC_CRS = "https://www.opengis.net/def/crs/"
EPSG_URI = OGC_CRS + "EPSG/0/{}"


def reference_system_uri(crs: pyproj.CRS) -> str:
    """The OGC URI of ``crs``: ``https://www.opengis.net/def/crs/EPSG/0/27700``; a compound CRS
    (grid + vertical datum) as its own EPSG code when it has one, else the OGC compound form
    ``https://www.opengis.net/def/crs-compound?1=<grid URI>&2=<vertical URI>``. InputError when
    the CRS (or a part of a compound) has no EPSG code."""
    code = crs.to_epsg()
    if code is not None:
        return EPSG_URI.format(code)
    if crs.is_compound and crs.sub_crs_list:
        parts = []
        for k, sub in enumerate(crs.sub_crs_list, start=1):
            c = sub.to_epsg()
            if c is None:
                raise InputError(f"the CRS part {sub.name!r} has no EPSG code: CityJSON names "
                                 "its reference system by an OGC URI", field="crs")
            parts.append(f"{k}={EPSG_URI.format(c)}")
        return "https://www.opengis.net/def/crs-compound?" + "&".join(parts)
    raise InputError(f"the CRS {crs.name!r} has no EPSG code: CityJSON names its reference "
                     "system by an OGC URI", field="crs")


def metadata_reference_system(uri: str) -> str:
    """What ``metadata.referenceSystem`` holds: ``uri``, except that the CityJSON 2.0 schema
    admits only ``.../def/crs/...`` URIs, so a compound URI gives its horizontal part (the
    heights' datum then is not stated in the file)."""
    if uri.startswith(OGC_CRS):
        return uri
    if "crs-compound?" in uri:
        first = uri.split("?", 1)[1].split("&", 1)[0]
        return first.split("=", 1)[1]
    raise InputError(f"not an OGC CRS URI: {uri!r}", field="crs")


def _finite(x: float) -> float | None:
    return float(x) if x is not None and math.isfinite(x) else None


def _attributes(model: BuildingModel) -> JSONObject:
    m = model.measures
    ours: dict[str, Any] = {
        "measuredHeight": m["measured_height"], "sigmaMeasuredHeight": m["sigma_measured_height"],
        "roofType": m["roof_type"], "volume": m["volume"], "sigmaVolume": m["sigma_volume"],
        "footprintArea": m["footprint_area"], "sigmaFootprintArea": m["sigma_footprint_area"],
        "eavesHeight": m["eaves_height"], "sigmaEavesHeight": m["sigma_eaves_height"],
        "ridgeHeight": m["ridge_height"], "sigmaRidgeHeight": m["sigma_ridge_height"],
        "groundHeight": m["ground_height"],
        "adjustmentSigma0": model.adjustment.get("sigma0"),
    }
    out: JSONObject = dict(model.spec.attributes)
    for k, v in ours.items():
        out[k] = v if isinstance(v, str) else _finite(v)
    return out


def city_json(models: Sequence[BuildingModel], reference_system: str, *,
              title: str | None = None) -> JSONObject:
    """The CityJSON 2.0 document of ``models`` (see the module docstring); ``reference_system``
    an OGC CRS URI (reference_system_uri). GeometryError when a shell is not a valid solid
    after quantisation; InputError for two buildings with one id."""
    ids = [m.id for m in models]
    dup = [i for k, i in enumerate(ids) if i in ids[:k]]
    if dup:
        raise InputError(f"two buildings have the id {dup[0]!r}", field="buildings")
    allv = np.vstack([m.vertices for m in models]) if models else np.zeros((0, 3))
    translate = np.floor(allv.min(axis=0)) if len(allv) else np.zeros(3)
    vertices: list[list[int]] = []
    index: dict[tuple[int, int, int], int] = {}
    objects: JSONObject = {}
    for model in models:
        q = np.rint((model.vertices - translate) / SCALE).astype(np.int64)
        local: list[int] = []
        for row in q.tolist():
            key = (row[0], row[1], row[2])
            if key not in index:
                index[key] = len(vertices)
                vertices.append(row)
            local.append(index[key])
        if len(set(local)) != len(local):
            raise GeometryError(f"building {model.id!r}: two of its vertices are less than "
                                f"{SCALE:g} CRS units apart")
        rings = [s.ring for s in model.surfaces]
        check_solid((q.astype(np.float64) - q.min(axis=0)) * SCALE, rings,
                    f"building {model.id!r}", planarity_m=QUANTISED_PLANARITY)
        kinds = sorted({s.kind for s in model.surfaces},
                       key=("RoofSurface", "WallSurface", "GroundSurface").index)
        shell = [[[local[v] for v in s.ring]] for s in model.surfaces]
        geometry = {"type": "Solid", "lod": LOD, "boundaries": [shell],
                    "semantics": {"surfaces": [{"type": k} for k in kinds],
                                  "values": [[kinds.index(s.kind) for s in model.surfaces]]}}
        objects[model.id] = {"type": "Building", "attributes": _attributes(model),
                             "geometry": [geometry]}
    metadata: JSONObject = {"referenceSystem": metadata_reference_system(reference_system)}
    if title:
        metadata["title"] = title
    if len(allv):
        lo, hi = allv.min(axis=0), allv.max(axis=0)
        metadata["geographicalExtent"] = [*map(float, lo), *map(float, hi)]
    return {"type": "CityJSON", "version": VERSION,
            "transform": {"scale": [SCALE, SCALE, SCALE], "translate": translate.tolist()},
            "metadata": metadata, "CityObjects": objects, "vertices": vertices}


def city_json_bytes(models: Sequence[BuildingModel], reference_system: str, *,
                    title: str | None = None) -> bytes:
    """city_json as UTF-8 bytes (what files and the API send, media type
    application/city+json)."""
    return orjson.dumps(city_json(models, reference_system, title=title))
