"""gsgeo.demo: a synthetic georeferenced 3DGS scene with ground truth.

- `scene`: the analytic geometry (building, poles, railing, sculpture, ground) and the 20
  validation points, with ray casting for visibility and the 2.5-D top surface;
- `splats`: Gaussian splats sampled on that geometry, written as an INRIA PLY (plyfile);
- `place`: where it is (EPSG:27700, Parker's Piece, Cambridge) and the truth in ECEF and grid;
- `build`: PLY -> `gsgeo tiles` -> DATA/scenes/demo, plus DATA/demo/checkpoints.csv;
- `project`: the project 'demo' with the truth as check points (gsgeo.store), and the
  project 'demo-local' with control and check points;
- `localframe`: the demo in an arbitrary local frame by an exactly known similarity (the
  un-georeferenced variant, as 3DGS trainers leave a scene);
- `localbuild`: that variant -> `gsgeo tiles` without georeference -> DATA/scenes/demo-local,
  plus its control, check points and truth in DATA/demo-local.
"""
