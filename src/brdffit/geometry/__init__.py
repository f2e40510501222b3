"""Geometry and parameterisations: spherical, Rusinkiewicz half/difference and slope space.

All functions are vectorised over leading axes. Directions are unit vectors in the local
shading frame (normal = +z), both ``wi`` and ``wo`` pointing away from the surface.
"""

from .frames import (
    cartesian_to_spherical,
    normalize,
    spherical_to_cartesian,
)
from .rusinkiewicz import half_diff_to_io, io_to_half_diff
from .slopes import normal_to_slope, slope_to_normal

__all__ = [
    "normalize",
    "spherical_to_cartesian",
    "cartesian_to_spherical",
    "io_to_half_diff",
    "half_diff_to_io",
    "slope_to_normal",
    "normal_to_slope",
]
