"""Binary glTF (GLB) tiles holding one SPZ-compressed Gaussian splat primitive, and their parsing.

Each tile is one mesh with one POINTS primitive whose attributes (POSITION, COLOR_0,
KHR_gaussian_splatting:SCALE, :ROTATION and for SH degree l >= 1 :SH_DEGREE_l_COEF_n) are
accessors without bufferViews; the SPZ blob is the primitive's
``KHR_gaussian_splatting_compression_spz_2.bufferView``. Node 0 carries an explicit matrix
turning the Z-up content into glTF's Y-up, which CesiumJS's Y-up -> Z-up turn cancels.
"""

from __future__ import annotations

import json
import struct

import numpy as np

from gsgeo.errors import InputError

EXT = "KHR_gaussian_splatting"
EXT_SPZ = "KHR_gaussian_splatting_compression_spz_2"
#: Z-up -> Y-up, column-major: (x, y, z) -> (x, z, -y).
Z_UP_TO_Y_UP = [1, 0, 0, 0, 0, 0, -1, 0, 0, 1, 0, 0, 0, 0, 0, 1]
#: CesiumJS's Y-up -> Z-up (rotation +90 degrees about x), row-major numpy.
Y_UP_TO_Z_UP = np.array([[1.0, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]])

_GLB_MAGIC = 0x46546C67


def _pad(b: bytes, fill: bytes) -> bytes:
    return b + fill * ((4 - len(b) % 4) % 4)


def tile_glb(spz: bytes, count: int, sh_degree: int, lo: np.ndarray, hi: np.ndarray) -> bytes:
    """A GLB holding one SPZ blob; lo/hi bound the splat centres (content frame, Z-up)."""
    # POSITION min/max are in the node's local coordinates, i.e. our Z-up content frame
    accessors = [
        {"componentType": 5126, "count": count, "type": "VEC3",
         "min": [float(v) for v in lo], "max": [float(v) for v in hi]},
        {"componentType": 5121, "normalized": True, "count": count, "type": "VEC4"},
        {"componentType": 5126, "count": count, "type": "VEC3"},
        {"componentType": 5126, "count": count, "type": "VEC4"},
    ]
    attributes = {"POSITION": 0, "COLOR_0": 1, f"{EXT}:SCALE": 2, f"{EXT}:ROTATION": 3}
    for degree in range(1, sh_degree + 1):
        for n in range(2 * degree + 1):
            attributes[f"{EXT}:SH_DEGREE_{degree}_COEF_{n}"] = len(accessors)
            accessors.append({"componentType": 5126, "count": count, "type": "VEC3"})
    gltf = {
        "asset": {"version": "2.0", "generator": "gsgeo tiles"},
        "extensionsUsed": [EXT, EXT_SPZ],
        "extensionsRequired": [EXT, EXT_SPZ],
        "buffers": [{"byteLength": len(spz)}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": len(spz)}],
        "accessors": accessors,
        "meshes": [{"primitives": [{
            "mode": 0, "attributes": attributes,
            "extensions": {EXT: {"extensions": {EXT_SPZ: {"bufferView": 0}}}},
        }]}],
        "nodes": [{"mesh": 0, "matrix": Z_UP_TO_Y_UP}],
        "scenes": [{"nodes": [0]}],
        "scene": 0,
    }
    js = _pad(json.dumps(gltf, separators=(",", ":")).encode(), b" ")
    binary = _pad(spz, b"\0")
    total = 12 + 8 + len(js) + 8 + len(binary)
    return b"".join([
        struct.pack("<III", _GLB_MAGIC, 2, total),
        struct.pack("<II", len(js), 0x4E4F534A), js,
        struct.pack("<II", len(binary), 0x004E4942), binary,
    ])


def _node_matrix(node: dict) -> np.ndarray:
    if "matrix" in node:
        return np.asarray(node["matrix"], float).reshape(4, 4).T
    m = np.eye(4)
    if "rotation" in node:
        from gsgeo.tiles.splats import quat_to_matrix
        m[:3, :3] = quat_to_matrix(np.asarray(node["rotation"], float))
    if "scale" in node:
        m[:3, :3] = m[:3, :3] * np.asarray(node["scale"], float)
    if "translation" in node:
        m[:3, 3] = node["translation"]
    return m


def parse_glb(data: bytes, where: str = "tile") -> list[tuple[bytes, np.ndarray]]:
    """SPZ blobs of a GLB's splat primitives with their node-to-glTF-root matrices (4x4)."""
    if len(data) < 20:
        raise InputError(f"{where}: too short for a GLB")
    magic, version, _ = struct.unpack("<III", data[:12])
    if magic != _GLB_MAGIC or version != 2:
        raise InputError(f"{where}: not a glTF 2.0 binary file")
    jlen, jtype = struct.unpack("<II", data[12:20])
    gltf = json.loads(data[20:20 + jlen])
    bin_chunk = b""
    o = 20 + jlen
    if o + 8 <= len(data):
        blen, _ = struct.unpack("<II", data[o:o + 8])
        bin_chunk = data[o + 8:o + 8 + blen]
    out: list[tuple[bytes, np.ndarray]] = []

    def visit(ni: int, parent: np.ndarray) -> None:
        node = gltf["nodes"][ni]
        m = parent @ _node_matrix(node)
        if "mesh" in node:
            for prim in gltf["meshes"][node["mesh"]]["primitives"]:
                spz = prim.get("extensions", {}).get(EXT, {}).get("extensions", {}).get(EXT_SPZ)
                if spz is None:
                    continue
                bv = gltf["bufferViews"][spz["bufferView"]]
                if bv.get("buffer", 0) != 0 or "uri" in gltf["buffers"][0]:
                    raise InputError(f"{where}: SPZ blob outside the GLB binary chunk")
                off = bv.get("byteOffset", 0)
                out.append((bin_chunk[off:off + bv["byteLength"]], m))
        for c in node.get("children", []):
            visit(c, m)

    scene = gltf.get("scenes", [{"nodes": list(range(len(gltf.get("nodes", []))))}])
    for ni in scene[gltf.get("scene", 0)]["nodes"]:
        visit(ni, np.eye(4))
    return out
