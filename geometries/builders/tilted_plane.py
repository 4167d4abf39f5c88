"""c'. A square plate under a plane tilted about y: spring length h(x) = gap + x tan(tilt), a
closed-form pressure p = E' d / h(x). Plain numpy, no mesher."""

from __future__ import annotations

import math

import numpy as np

from geometries.builders.common import BuiltGeometry, Param, validate_parameters
from geometries.builders.flat_plates import PLATE_PARAMS, plates
from geometries.errors import InputError


TILTED_PARAMS = dict(PLATE_PARAMS, tilt_deg=Param("float", -60.0, 60.0))


def tilted_plane(width_mm: float = 20.0, depth_mm: float = 20.0, gap_mm: float = 2.0,
                 tilt_deg: float = 2.0, n_per_side: int = 20) -> BuiltGeometry:
    """Square plate (as in :func:`~geometries.builders.flat_plates.flat_plates`) under a plane through (0, 0, gap_mm) tilted about
    the y axis: the spring length is h(x) = gap_mm + x tan(tilt_deg), exact for every centroid;
    under a rigid normal approach d the pressure is p = E' d / h(x) (closed form). The plane must
    stay above the plate: gap_mm > width/2 * |tan(tilt)|."""
    p = validate_parameters("tilted_plane", TILTED_PARAMS, dict(locals()))
    if p["width_mm"] / 2 * abs(math.tan(math.radians(p["tilt_deg"]))) >= p["gap_mm"]:
        raise InputError("tilted_plane: the tilted plane would touch or cut the plate",
                         key="geometry.tilt_deg",
                         expected=f"width_mm/2 * |tan(tilt)| < gap_mm ({p['gap_mm']:g})")
    mobile, fixed = plates(p["width_mm"], p["depth_mm"], p["gap_mm"], p["tilt_deg"],
                            p["n_per_side"])
    return BuiltGeometry(
        mobile=mobile, fixed=fixed, reference_point_mm=None,
        ankle_axis_point_mm=np.zeros(3), ankle_axis_direction=np.array([1.0, 0.0, 0.0]),
        ligaments=(),
        description=(f"Flat plate {p['width_mm']:g} x {p['depth_mm']:g} mm under a plane tilted "
                     f"{p['tilt_deg']:g} deg about y, h(x) = {p['gap_mm']:g} + x tan(tilt): "
                     "closed-form pressure p = E' d / h(x). The ankle axis is nominal."),
        parameters=p,
    )
