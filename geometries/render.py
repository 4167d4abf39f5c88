"""Off-screen picture of a built geometry (pyvista, imported only here).

``render_geometry_png`` draws the talus (mobile surface, coloured by candidate spring length as
cell data where a length is given: springs longer than h_max or without a hit are grey), the
tibia (translucent), the ankle axis and the ligaments as lines, with a legend and an anatomical
triad (conventions: +x lateral, +y anterior, +z superior). pyvista runs off-screen:
:func:`quiet_offscreen_vtk` silences VTK's notice about a missing X server (VTK falls back to
OSMesa/EGL; the notice is harmless). :func:`add_orientation_triad` is shared with the report's
pressure maps.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from geometries.builders import BuiltGeometry
from geometries.extras import import_extra
from geometries.surface import TriangleSurface

__all__ = ["render_geometry_png", "quiet_offscreen_vtk", "add_orientation_triad", "colour_bar_args", "place_bar_title"]

def quiet_offscreen_vtk() -> None:
    """Off-screen pyvista without VTK's "bad X server connection" notice on stderr.

    The notice is a vtkLogger WARN printed when no DISPLAY is set, before VTK falls back to an
    off-screen context; errors still reach stderr.
    """
    pv = import_extra("pyvista", "rendering")
    from vtkmodules.vtkCommonCore import vtkLogger

    vtkLogger.SetStderrVerbosity(vtkLogger.VERBOSITY_ERROR)
    pv.OFF_SCREEN = True


def colour_bar_args(title: str, **extra) -> dict:
    """pyvista ``scalar_bar_args`` of a horizontal colour bar at the bottom of a panel.

    Call :func:`place_bar_title` after ``add_mesh``: it moves the tick labels under the bar and
    writes the title above it, where VTK's own layout would draw the title over the labels.
    """
    return {"title": title, "color": "black", "vertical": False, "position_x": 0.12, "position_y": 0.05, "width": 0.76, "height": 0.1,
            "fmt": "%.3g", "label_font_size": 14, **extra}


def place_bar_title(plotter, title: str, font_size: int = 11) -> None:
    """Labels of the colour bar ``title`` under its bar, its title centred above it (see colour_bar_args)."""
    bar = plotter.scalar_bars[title]
    bar.SetTextPositionToPrecedeScalarBar()
    bar.SetTitle("")
    x, y = bar.GetPosition()
    width, height = bar.GetPosition2()
    text = plotter.add_text(title, position=(x + width / 2.0, y + height + 0.01), viewport=True, font_size=font_size, color="black")
    text.GetTextProperty().SetJustificationToCentered()


def add_orientation_triad(plotter, anatomical: bool, viewport: tuple[float, float, float, float] = (0.0, 0.0, 0.2, 0.2)) -> None:
    """An axes triad in the active renderer's corner, turning with its camera.

    ``anatomical``: label the axes with the ankle's directions (x lateral, y anterior, z
    superior) instead of plain x, y, z.
    """
    labels = ("x lat", "y ant", "z sup") if anatomical else ("x", "y", "z")
    plotter.add_axes(xlabel=labels[0], ylabel=labels[1], zlabel=labels[2], line_width=3, color="black", viewport=viewport)


def _polydata(surface: TriangleSurface):  # -> pyvista.PolyData
    pv = import_extra("pyvista", "rendering")

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
    pv = import_extra("pyvista", "rendering")

    quiet_offscreen_vtk()
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
            scalar_bar_args=colour_bar_args("spring length (mm)", position_x=0.35, width=0.6, height=0.1),
        )
        place_bar_title(plotter, "spring length (mm)")
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

    legend = [["talus (M)", "wheat" if spring_length_mm is None else "lightgrey"], ["tibia (F)", "steelblue"], ["ankle axis", "black"]]
    if built.ligaments:
        legend.append(["ligaments", "firebrick"])
        mids = np.array([(np.asarray(lig.mobile_point_mm) + np.asarray(lig.fixed_point_mm)) / 2.0 for lig in built.ligaments])
        plotter.add_point_labels(mids, [lig.name for lig in built.ligaments], font_size=14, text_color="firebrick",
                                 shape_color="white", shape_opacity=0.7, show_points=False, always_visible=True)
    plotter.add_legend(legend, bcolor="white", border=True, size=(0.22, 0.18), loc="upper right", face="rectangle")
    add_orientation_triad(plotter, anatomical=bool(built.ligaments))  # the ankle builders, which attach ligaments
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
