"""c. A square plate under a parallel plane, for closed-form tests: uniform spring length and
pressure. Structured grids in plain numpy, no mesher."""

from __future__ import annotations

import math

import numpy as np

from geometries.builders.common import BuiltGeometry, Param, validate_parameters
from geometries.surface import TriangleSurface


PLATE_PARAMS = {
    "width_mm": Param("float", 0.0, 1e4, lo_open=True),
    "depth_mm": Param("float", 0.0, 1e4, lo_open=True),
    "gap_mm": Param("float", 0.0, 1e4, lo_open=True),
    "n_per_side": Param("int", 1, 2000),
}


def structured_grid(x0: float, x1: float, y0: float, y1: float, nx: int, ny: int,
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Structured triangulated rectangle in the z = 0 plane, triangles with normal +z."""
    xs = np.linspace(x0, x1, nx + 1)
    ys = np.linspace(y0, y1, ny + 1)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    verts = np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    i, j = i.ravel(), j.ravel()
    v00 = i * (ny + 1) + j
    v10 = (i + 1) * (ny + 1) + j
    v01 = i * (ny + 1) + j + 1
    v11 = (i + 1) * (ny + 1) + j + 1
    tris = np.concatenate([np.column_stack([v00, v10, v11]), np.column_stack([v00, v11, v01])])
    return verts, tris.astype(np.int64)


def plates(width_mm: float, depth_mm: float, gap_mm: float, tilt_deg: float,
           n_per_side: int) -> tuple[TriangleSurface, TriangleSurface]:
    verts, tris = structured_grid(-width_mm / 2, width_mm / 2, -depth_mm / 2, depth_mm / 2,
                                  n_per_side, n_per_side)
    mobile = TriangleSurface(verts, tris, name="plate", source="plates")
    # fixed plane: larger than the plate by a margin, through (0, 0, gap), rotated about y
    mx, my = width_mm / 2 + max(width_mm, depth_mm) / 2, depth_mm / 2 + max(width_mm, depth_mm) / 2
    t = math.tan(math.radians(tilt_deg))
    corners = np.array([[-mx, -my], [mx, -my], [mx, my], [-mx, my]])
    fv = np.column_stack([corners, gap_mm + corners[:, 0] * t])
    fixed = TriangleSurface(fv, np.array([[0, 2, 1], [0, 3, 2]], dtype=np.int64),
                            name="plane", source="plates")  # normal points down
    return mobile, fixed


def flat_plates(width_mm: float = 20.0, depth_mm: float = 20.0, gap_mm: float = 2.0,
                n_per_side: int = 20) -> BuiltGeometry:
    """Square plate (mobile, z = 0, normal +z, a structured grid of n_per_side^2 squares split
    into 2 n_per_side^2 triangles) under a parallel plane at z = ``gap_mm`` (fixed, normal -z,
    two triangles, larger than the plate so every ray hits). Every spring has length gap_mm:
    under a normal force F the pressure is uniform, F / (width * depth)."""
    p = validate_parameters("flat_plates", PLATE_PARAMS, dict(locals()))
    mobile, fixed = plates(p["width_mm"], p["depth_mm"], p["gap_mm"], 0.0, p["n_per_side"])
    return BuiltGeometry(
        mobile=mobile, fixed=fixed, reference_point_mm=None,
        ankle_axis_point_mm=np.zeros(3), ankle_axis_direction=np.array([1.0, 0.0, 0.0]),
        ligaments=(),
        description=(f"Flat plate {p['width_mm']:g} x {p['depth_mm']:g} mm under a parallel plane "
                     f"{p['gap_mm']:g} mm above: uniform spring length, uniform pressure F/A "
                     "(closed form). The ankle axis is nominal (x through the origin)."),
        parameters=p,
    )
