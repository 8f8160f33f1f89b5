"""Georeferencing a scene by control points: the similarity fit, its blunder tests and the
mapping of control into the scene's frame (see :mod:`gsgeo.georef.helmert`)."""
