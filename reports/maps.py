"""Pressure maps of two result directories side by side (pyvista off-screen, imported only here).

Three panels: side a (EDEM/DEM), side b (the FE reference, or another run) and their difference
a - b on a's surface (b at a's spring centroids, paired as in the L2 metric (docs/method.md#7-comparison-metrics)). a and b
share one colour scale [0, p_max]; the difference uses the same span, [-p_max, p_max], on a
diverging map whose middle is white, so colours compare across the three panels and exact
agreement is white. Every panel is drawn unlit (flat colours), so a colour reads off its bar.
The contact outline (edges between triangles in and out of contact) is drawn on each panel.

Orientation: on the built-in ankles (docs/conventions.md: +x lateral, +y anterior, +z superior)
the maps look down on the talus from above, anterior up the page and lateral to the right, and
each panel is labelled anterior/posterior/medial/lateral; every panel carries an axes triad.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

from geometries.errors import InputError
from edem.resultdir import read_result_dir
from verification.metrics import pressure_at_cells, project_onto_surface, same_mesh


def contact_outline_edges(triangles: np.ndarray, in_contact: np.ndarray) -> np.ndarray:
    """(n, 2) vertex pairs of the edges bounding the contact region of a triangulated surface.

    An edge is on the outline when exactly one of the triangles sharing it is in contact: the
    edges between contact and no contact, and the surface's boundary edges of contact triangles.
    """
    tris = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    contact = np.asarray(in_contact, dtype=bool).reshape(-1)
    edges = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    owner_in_contact = np.tile(contact, 3)
    unique, inverse = np.unique(edges, axis=0, return_inverse=True)
    count = np.bincount(inverse.reshape(-1), weights=owner_in_contact.astype(float), minlength=len(unique))
    return unique[count == 1]


def _polydata(frame, cell_scalars: dict[str, np.ndarray] | None = None, point_scalars: dict[str, np.ndarray] | None = None):
    import pyvista as pv

    tris = frame.triangles
    faces = np.hstack([np.full((len(tris), 1), 3, dtype=np.int64), tris]).ravel()
    mesh = pv.PolyData(frame.points_mm, faces)
    for name, values in (cell_scalars or {}).items():
        mesh.cell_data[name] = values
    for name, values in (point_scalars or {}).items():
        mesh.point_data[name] = values
    return mesh


def _outline(frame, contact: np.ndarray, towards_viewer: np.ndarray):
    """The contact outline as lines, lifted slightly towards the viewer so the surface does not hide it."""
    import pyvista as pv

    edges = contact_outline_edges(frame.triangles, contact)
    if edges.size == 0:
        return None
    lines = np.hstack([np.full((len(edges), 1), 2, dtype=np.int64), edges]).ravel()
    size = float(np.linalg.norm(np.ptp(frame.points_mm, axis=0)))
    return pv.PolyData(frame.points_mm + 2e-3 * size * towards_viewer, lines=lines)


def _contact(frame, pressure_cells: np.ndarray) -> np.ndarray:
    if "in_contact" in frame.cell_data:
        return frame.cell_data["in_contact"] > 0
    return pressure_cells > 0


def _frame_at(result, time_s: float):
    """The pressure map of a result directory at ``time_s`` (InputError naming pressure.pvd if none)."""
    times = np.array([t for t, _ in result.frames])
    j = int(np.argmin(np.abs(times - time_s)))
    if not np.isclose(times[j], time_s, rtol=1e-9, atol=1e-9):
        raise InputError(f"no pressure map at t = {time_s:g} s", file=result.path / "pressure.pvd", expected="a <DataSet> at that time")
    return result.frame(j)


ANKLE_BUILDERS = ("ideal_ankle", "subject_ankle")


def is_anatomical(result_dir: str | Path) -> bool:
    """True when a result directory's scene is one of the built-in ankles (anatomical axes).

    Read from the resolved scene (``scene.toml``) the run wrote, else from the built-in scene of
    summary.json's ``scene`` name; False when neither says.
    """
    import json
    import tomllib

    result_dir = Path(result_dir)
    path = result_dir / "scene.toml"
    if not path.is_file():
        try:
            from edem.scene import builtin_scene_names, resolve_scene_path

            name = json.loads((result_dir / "summary.json").read_text(encoding="utf-8")).get("scene", "")
            if name not in builtin_scene_names():
                return False
            path = resolve_scene_path(name)
        except (OSError, ValueError):
            return False
    try:
        return tomllib.loads(path.read_text(encoding="utf-8")).get("geometry", {}).get("builtin") in ANKLE_BUILDERS
    except (OSError, tomllib.TOMLDecodeError):
        return False


def _label_directions(plotter) -> None:
    """anterior/posterior/medial/lateral around the active panel (superior view, anterior up)."""
    for text, position in (("anterior", (0.5, 0.9)), ("posterior", (0.5, 0.2)), ("medial", (0.03, 0.55)), ("lateral", (0.97, 0.55))):
        actor = plotter.add_text(text, position=position, viewport=True, font_size=11, color="dimgray")
        prop = actor.GetTextProperty()
        prop.SetJustificationToCentered() if position[0] == 0.5 else (prop.SetJustificationToLeft() if position[0] < 0.5 else prop.SetJustificationToRight())
        prop.SetItalic(True)


#: width of a heading's character at font size 10 (px, VTK's default font, with a margin)
HEADING_PX_PER_CHAR = 8


def render_pressure_maps(
    a_dir: str | Path,
    b_dir: str | Path,
    out_png: str | Path,
    *,
    time_index: int = -1,
    labels: tuple[str, str] | None = None,
    window_size: tuple[int, int] = (1500, 600),
    time_s: float | None = None,
    title: str | None = None,
    anatomical: bool | None = None,
) -> Path:
    """PNG of a's pressure, b's pressure and a - b at one time point (default: the last one).

    When both directories have the same time points, ``time_index`` picks the same one in both;
    otherwise each directory's last time point is drawn. ``time_s`` instead picks the pressure
    map at that time in each directory (both must have one there: e.g. an FE reference solved at
    selected instants of a series). b's nodal pressure (FE point data) is drawn interpolated, cell
    pressure piecewise constant. ``anatomical`` (default: :func:`is_anatomical` of a): the
    superior view of an ankle with direction labels; otherwise the view looks at a's contact
    region along its mean normal. ``title`` is written above the panels.
    """
    import pyvista as pv

    heading = title
    a, b = read_result_dir(a_dir), read_result_dir(b_dir)
    if time_s is not None:
        frame_a, frame_b = _frame_at(a, time_s), _frame_at(b, time_s)
    else:
        same = a.time_s.shape == b.time_s.shape and np.allclose(a.time_s, b.time_s)
        ka = time_index if same else -1
        kb = time_index if same else -1
        frame_a, frame_b = a.frame(ka), b.frame(kb)
    label_a, label_b = labels or (str(a.summary.get("method", "a")), str(b.summary.get("method", "b")))
    if label_a == label_b:  # scalar bars are told apart by their titles
        label_a, label_b = f"{label_a} (a)", f"{label_b} (b)"

    p_a = pressure_at_cells(frame_a)
    b_nodal = "pressure_mpa" in frame_b.point_data
    if not b_nodal and same_mesh(frame_a, frame_b):
        p_b_at_a = frame_b.cell_data["pressure_mpa"]  # the same springs (as in the L2 metric)
    else:
        proj = project_onto_surface(frame_b.points_mm, frame_b.triangles, frame_a.centroids_mm)
        if b_nodal:
            p_b_at_a = np.einsum("ij,ij->i", proj.barycentric, frame_b.point_data["pressure_mpa"][frame_b.triangles[proj.triangle]])
        else:
            p_b_at_a = frame_b.cell_data["pressure_mpa"][proj.triangle]
    p_b_cells = pressure_at_cells(frame_b)
    p_max = float(max(np.max(p_a, initial=0.0), np.max(p_b_cells, initial=0.0), 1e-12))
    if b_nodal:
        p_max = max(p_max, float(np.max(frame_b.point_data["pressure_mpa"], initial=0.0)))

    contact_a = _contact(frame_a, p_a)
    contact_b = _contact(frame_b, p_b_cells)
    areas = frame_a.areas_mm2
    normals = np.cross(
        frame_a.points_mm[frame_a.triangles[:, 1]] - frame_a.points_mm[frame_a.triangles[:, 0]],
        frame_a.points_mm[frame_a.triangles[:, 2]] - frame_a.points_mm[frame_a.triangles[:, 0]],
    )
    if anatomical is None:
        anatomical = is_anatomical(a_dir)
    if anatomical:  # from above: camera on +z (superior), anterior (+y) up, so lateral (+x) is right
        view, up = np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0])
    else:
        region = contact_a if contact_a.any() else areas > 0
        view = normals[region].sum(axis=0)
        view = view / np.linalg.norm(view) if np.linalg.norm(view) > 0 else np.array([0.0, 0.0, 1.0])
        up = np.eye(3)[int(np.argmin(np.abs(view)))]
        up = up - (up @ view) * view

    from geometries.render import add_orientation_triad, colour_bar_args, place_bar_title, quiet_offscreen_vtk

    quiet_offscreen_vtk()
    plotter = pv.Plotter(shape=(1, 3), off_screen=True, window_size=list(window_size), border=False)
    plotter.set_background("white")
    panels = [
        (frame_a, {"pressure_mpa": p_a}, None, "pressure_mpa", (0.0, p_max), "viridis", f"{label_a}: pressure (MPa)", contact_a),
        (
            frame_b,
            None if b_nodal else {"pressure_mpa": p_b_cells},
            {"pressure_mpa": frame_b.point_data["pressure_mpa"]} if b_nodal else None,
            "pressure_mpa",
            (0.0, p_max),
            "viridis",
            f"{label_b}: pressure (MPa)",
            contact_b,
        ),
        (frame_a, {"difference_mpa": p_a - p_b_at_a}, None, "difference_mpa", (-p_max, p_max), "bwr", f"{label_a} - {label_b} (MPa)", contact_a),
    ]
    for column, (frame, cells, points, scalars, clim, cmap, title, contact) in enumerate(panels):
        plotter.subplot(0, column)
        mesh = _polydata(frame, cells, points)
        # unlit: a lit surface shades exact zero (white on "bwr") to grey and shifts every colour off its bar
        plotter.add_mesh(mesh, scalars=scalars, clim=clim, cmap=cmap, preference="point" if points else "cell", lighting=False,
                         scalar_bar_args=colour_bar_args(title))
        place_bar_title(plotter, title)
        outline = _outline(frame, contact, view)
        if outline is not None:
            plotter.add_mesh(outline, color="black", line_width=2)
        plotter.view_vector(view, viewup=up)
        plotter.reset_camera()
        plotter.camera.zoom(0.8)  # room for the direction labels and the colour bar
        border = mesh.extract_feature_edges(boundary_edges=True, feature_edges=False, manifold_edges=False, non_manifold_edges=False)
        if border.n_cells:  # the surface's rim, so a white difference panel still shows the talus
            plotter.add_mesh(border, color="darkgray", line_width=1)
        add_orientation_triad(plotter, anatomical, viewport=(0.0, 0.2, 0.2, 0.42))
        if anatomical:
            _label_directions(plotter)
    plotter.link_views()
    if heading:  # written in the first panel: wrapped to its width (about 8 px a character at font size 10)
        plotter.subplot(0, 0)
        plotter.add_text(textwrap.fill(heading, width=max(20, window_size[0] // 3 // HEADING_PX_PER_CHAR)), position="upper_left", font_size=10, color="black")
    out = Path(out_png)
    out.parent.mkdir(parents=True, exist_ok=True)
    plotter.screenshot(str(out))
    plotter.close()
    return out
