"""gsgeo.tiles: 3DGS PLY/SPZ reading, SPZ encoding, LOD tiling, georeferenced 3D Tiles writing
and reading back in ECEF (see build.build_tileset and reader.read_tileset)."""
