"""gsgeo: survey-grade point measurement in georeferenced 3D Gaussian Splatting scenes."""

from gsgeo.errors import GsgeoError, InputError

__version__ = "0.1.0"

__all__ = ["GsgeoError", "InputError", "__version__"]
