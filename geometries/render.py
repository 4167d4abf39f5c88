"""Off-screen picture of a built geometry (pyvista, imported only here).

``render_geometry_png`` draws the talus (mobile surface, coloured by candidate spring length as
cell data where a length is given: springs longer than h_max or without a hit are grey), the
tibia (translucent), the ankle axis and the ligaments as lines. pyvista runs off-screen; a
warning about a missing X server is harmless (VTK falls back to OSMesa/EGL).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from geometries.builders import BuiltGeometry
from geometries.surface import TriangleSurface

__all__ = ["render_geometry_png"]


def _polydata(surface: TriangleSurface):  # -> pyvista.PolyData
    import pyvista as pv

    tri = np.asarray(surface.triangles, dtype=np.int64)
    faces = np.hstack([np.full((len(tri), 1), 3, dtype=np.int64), tri]).ravel()
    return pv.PolyData(np.asarray(surface.vertices_mm, dtype=np.float64), faces)


def render_geometry_png(
    built: BuiltGeometry,
    path: str | Path,
    spring_length_mm: np.ndarray | None = None,
    max_spring_length_mm: float = 3.5,
    window_size: tuple[int, int] = (1024, 768),
    title: str | None = None,
) -> Path:
    """Write a PNG of ``built`` to ``path`` and return the path.

    ``spring_length_mm`` (one value per mobile triangle; ``inf``/``nan`` = no hit) colours the
    candidate springs (0 < h <= ``max_spring_length_mm``) on the talus as cell data; other
    triangles are drawn grey. Without it the talus is drawn in a plain bone colour.
    """
    import pyvista as pv

    pv.OFF_SCREEN = True
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)

    talus = _polydata(built.mobile)
    tibia = _polydata(built.fixed)
    plotter = pv.Plotter(off_screen=True, window_size=list(window_size))
    plotter.set_background("white")

    if spring_length_mm is not None:
        h = np.asarray(spring_length_mm, dtype=np.float64).reshape(-1)
        if h.shape[0] != built.mobile.n_triangles:
            raise ValueError(
                f"spring_length_mm has {h.shape[0]} values for {built.mobile.n_triangles} triangles"
            )
        candidate = np.isfinite(h) & (h > 0) & (h <= max_spring_length_mm)
        talus.cell_data["spring_length_mm"] = np.where(candidate, h, np.nan)
        plotter.add_mesh(
            talus,
            scalars="spring_length_mm",
            cmap="viridis",
            clim=(0.0, float(max_spring_length_mm)),
            nan_color="lightgrey",
            show_edges=False,
            scalar_bar_args={"title": "spring length (mm)", "color": "black"},
        )
    else:
        plotter.add_mesh(talus, color="wheat", show_edges=False)

    plotter.add_mesh(tibia, color="steelblue", opacity=0.35, show_edges=True, edge_color="navy",
                     line_width=0.5)

    # ankle axis
    p0 = np.asarray(built.ankle_axis_point_mm, dtype=np.float64)
    d = np.asarray(built.ankle_axis_direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    extent = float(np.ptp(built.mobile.vertices_mm, axis=0).max())
    plotter.add_mesh(pv.Line(p0 - 0.7 * extent * d, p0 + 0.7 * extent * d), color="black",
                     line_width=2)

    # ligaments
    for lig in built.ligaments:
        a = np.asarray(lig.mobile_point_mm, dtype=np.float64)
        b = np.asarray(lig.fixed_point_mm, dtype=np.float64)
        plotter.add_mesh(pv.Line(a, b), color="firebrick", line_width=4)
        plotter.add_mesh(pv.PolyData(np.vstack([a, b])), color="firebrick", point_size=8,
                         render_points_as_spheres=True)

    if title:
        plotter.add_text(title, font_size=10, color="black")
    # camera: from antero-lateral and above, framing the talus and the ligaments (the tibia
    # planes of the idealised model are much larger than the talus and are left cropped)
    pts = [built.mobile.vertices_mm]
    for lig in built.ligaments:
        pts.append(np.vstack([lig.mobile_point_mm, lig.fixed_point_mm]))
    pts = np.vstack(pts)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    plotter.view_vector((1.0, 0.9, 0.8), viewup=(0.0, 0.0, 1.0))
    plotter.reset_camera(bounds=(lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]))
    plotter.camera.zoom(1.1)
    plotter.screenshot(str(path))
    plotter.close()
    return path
