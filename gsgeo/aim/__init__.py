"""Aiming aids over a scene's splats and its rendered views (server side of auto-aim).

- ``splatindex``: a scene's splats held once per tileset version (centres, sizes,
  orientations, alpha) in the tileset's ECEF;
- ``depth``: where along a ray the splats are (depth hint, near/far bounds);
- ``camera``: the viewer's pinhole camera (projection, pick rays, epipolar segments);
- ``views``: suggested viewpoints that most reduce a point's predicted uncertainty;
- ``match``: finding a clicked feature in another rendered view (OpenCV).
"""
