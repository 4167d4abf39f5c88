"""Scenes from an OpenSim model: the two bodies' meshes and their relative pose over a motion.

The `[opensim]` scene section names a `.osim` model, the mobile body M (it carries the springs)
and the fixed body F, and a motion (`.mot`/`.sto` of coordinate values, e.g. an IK result):

    [opensim]
    model = "subject01.osim"
    mobile_body = "talus_r"
    fixed_body = "tibia_r"
    motion = "walk_ik.mot"
    # mobile_meshes = ["talus.vtp"]   # default: every mesh attached to the body
    # fixed_meshes = ["tibia_r.vtp"]
    # geometry_path = ["../Geometry"] # more folders to search for mesh files

Frames and units: the scene frame is M's body frame, in mm (OpenSim's axes: x anterior, y up,
z right for the usual models). F's mesh stays in F's own body frame and is placed at every time
point by the pose of F in M's frame from the model at the motion's coordinates (all of them,
interpolated linearly to the load's times), so EDEM/DEM see the true relative pose, not one
joint angle. Mesh files are found as OpenSim finds them: as given if absolute, next to the
model, in its `Geometry` folder, then in `geometry_path`; each mesh is scaled by its
`scale_factors` and placed by the frame it is attached to.

The `opensim` package (the optional extra `opensim`) is imported only here, and only when a
scene has an `[opensim]` section.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from geometries.errors import InputError
from edem.plausibility import check_load_bodies, check_motion_units
from edem.tables import SceneTable
from geometries.mesh_files import MAX_COORDINATE_MM
from geometries.surface import TriangleSurface

if TYPE_CHECKING:
    from edem.loads import LoadSeries
    from edem.springs import Cartilage

OPENSIM_KEYS = {"model", "mobile_body", "fixed_body", "motion", "mobile_meshes", "fixed_meshes", "geometry_path"}
M_TO_MM = 1000.0


@dataclass(frozen=True, eq=False)
class BodyPoses:
    """Pose of F in M's frame per time point: x_M = R_k x_F + t_k (mm), and the coordinates used.

    ``coordinates`` maps each model coordinate to its values (n,) in the motion's units turned
    into SI (rad or m), for the result files.
    """

    rotation: np.ndarray  # (n, 3, 3)
    translation_mm: np.ndarray  # (n, 3)
    coordinates: dict[str, np.ndarray]
    mobile_in_ground_rotation: np.ndarray  # (n, 3, 3) R_GM: M's axes in ground
    mobile_in_ground_mm: np.ndarray  # (n, 3) M's origin in ground

    def placed_vertices_mm(self, surface: TriangleSurface, k: int) -> np.ndarray:
        """F's vertices at time point k, in the scene (M's) frame."""
        return surface.vertices_mm @ self.rotation[k].T + self.translation_mm[k]


@dataclass(frozen=True, eq=False)
class OpenSimBodies:
    """What an `[opensim]` section gives the scene: both surfaces (M in M's frame, F in F's) and F's poses."""

    mobile: TriangleSurface
    fixed: TriangleSurface
    poses: BodyPoses
    warnings: tuple[str, ...]


def import_opensim():
    """The opensim module, or InputError saying how to install it."""
    try:
        import opensim
    except ImportError as exc:
        raise InputError(
            f"the scene has an [opensim] section but the opensim package cannot be imported ({exc})",
            key="opensim",
            expected="the optional extra: pip install -e '.[opensim]' (the opensim 4.6 wheel, Python 3.12)",
        ) from None
    opensim.Logger.removeFileSink()  # no opensim.log in the user's working directory
    return opensim


def _matrix(rotation) -> np.ndarray:
    mat = rotation.asMat33()
    return np.array([[mat.get(i, j) for j in range(3)] for i in range(3)])


def _vector(vec) -> np.ndarray:
    return np.array([vec.get(i) for i in range(3)])


def find_geometry_file(name: str, model_file: Path, search_path: list[Path]) -> tuple[Path | None, list[Path]]:
    """OpenSim's search order for a mesh file: absolute, the model's folder, its Geometry folder, then ``search_path``."""
    given = Path(name)
    attempts = [given] if given.is_absolute() else [model_file.parent / given, model_file.parent / "Geometry" / given]
    attempts += [folder / given for folder in search_path if not given.is_absolute()]
    for path in attempts:
        if path.is_file():
            return path, attempts
    return None, attempts


def body_surface(osim, model, body_name: str, model_file: Path, search_path: list[Path], only: list[str] | None, key: str) -> TriangleSurface:
    """Every mesh attached to a body (or to frames fixed on it), scaled and placed in its frame, in mm, merged."""
    from geometries.mesh_files import read_surface
    from geometries.repair import check_units, clean_surface

    meshes = []
    for component in model.getComponentsList():
        if component.getConcreteClassName() == "Mesh":
            mesh = osim.Mesh.safeDownCast(component)
            frame = mesh.getFrame()
            if frame.findBaseFrame().getName() == body_name:
                meshes.append((mesh.get_mesh_file(), _vector(mesh.get_scale_factors()), frame.findTransformInBaseFrame()))
    names = [m[0] for m in meshes]
    if only is not None:
        missing = [n for n in only if n not in names]
        if missing:
            raise InputError(f"body '{body_name}' has no mesh {missing[0]!r}", file=model_file, key=key, expected="one of " + (", ".join(names) or "(no mesh attached)"))
        meshes = [m for m in meshes if m[0] in only]
    if not meshes:
        raise InputError(f"body '{body_name}' has no mesh geometry attached", file=model_file, key=key, expected="a body with a Mesh (attached_geometry) to take its surface from")
    vertices, triangles, offset = [], [], 0
    for name, scale, transform in meshes:
        path, attempts = find_geometry_file(name, model_file, search_path)
        if path is None:
            raise InputError(
                f"mesh file {name!r} of body '{body_name}' not found (looked in {', '.join(str(a) for a in attempts)})",
                file=model_file, key=key, expected="the mesh next to the model, in its Geometry folder, or in [opensim] geometry_path",
            )
        surface = read_surface(path, units="m", key=key, name=body_name)
        # scale about the mesh frame's origin, then place the mesh frame in the body frame (m -> mm)
        placed = surface.vertices_mm * scale
        placed = placed @ _matrix(transform.R()).T + _vector(transform.p()) * M_TO_MM
        # A NaN or huge scale factor or frame offset in the model (a fuzz found them) would
        # reach the KD-trees and the ray caster as non-finite points.
        if not (np.all(np.isfinite(placed)) and np.abs(placed).max(initial=0.0) <= MAX_COORDINATE_MM):
            raise InputError(
                f"body '{body_name}': its mesh {name!r}, scaled by {scale.tolist()} and placed by its frame, has vertices "
                f"that are not finite or lie beyond {MAX_COORDINATE_MM:g} mm", file=model_file, key=key,
                expected="finite scale_factors and frame locations and orientations that keep the bone within a metre or so",
            )
        vertices.append(placed)
        triangles.append(surface.triangles + offset)
        offset += len(placed)
    merged = TriangleSurface(np.vstack(vertices), np.vstack(triangles), name=body_name, source=str(model_file))
    check_units(merged, "m", refuse=True, key=key)
    return clean_surface(merged, key=key)


def _motion_coordinates(osim, model, motion_file: Path, time_s: np.ndarray, key: str) -> tuple[dict[str, np.ndarray], list[str], list[str]]:
    """Every model coordinate the motion gives, in SI (rad, m), linearly interpolated to ``time_s``;
    the names of the coordinates it leaves at their defaults; and warnings."""
    from edem.loads import read_opensim_table

    data = read_opensim_table(motion_file, key)
    file_time = data.column("time", key)
    data.check_time(file_time, key)
    tol = 1e-9 * max(1.0, file_time[-1] - file_time[0])
    if time_s.min() < file_time[0] - tol or time_s.max() > file_time[-1] + tol:
        raise InputError(
            f"the load's times [{time_s.min():g}, {time_s.max():g}] s fall outside the motion's [{file_time[0]:g}, {file_time[-1]:g}] s",
            file=motion_file, key=key, expected="a motion covering every load time point (or [load] time_range_s)",
        )
    columns = {c.split("/")[-2] if c.endswith("/value") else c: c for c in data.columns}
    values: dict[str, np.ndarray] = {}
    missing: list[str] = []
    notes: list[str] = []
    coordinate_set = model.getCoordinateSet()
    for i in range(coordinate_set.getSize()):
        coordinate = coordinate_set.get(i)
        name = coordinate.getName()
        if name not in columns:
            missing.append(name)
            continue
        column = data.column(columns[name], key)
        if coordinate.getMotionType() == osim.Coordinate.Rotational:
            notes += check_motion_units(name, column, data.in_degrees, (coordinate.getRangeMin(), coordinate.getRangeMax()), motion_file, key)
            if data.in_degrees:
                column = np.radians(column)
        values[name] = np.interp(np.clip(time_s, file_time[0], file_time[-1]), file_time, column)
    if not values:
        raise InputError("no column of the motion names a coordinate of the model", file=motion_file, key=key,
                         expected="coordinate names (e.g. ankle_angle_r) or paths ending in /<coordinate>/value")
    return values, missing, notes


def load_opensim_bodies(table: dict[str, Any], scene_file: Path, time_s: np.ndarray) -> OpenSimBodies:
    """Build both surfaces and F's pose in M's frame at every load time point from an `[opensim]` table."""
    tab = SceneTable(table, scene_file, "opensim", OPENSIM_KEYS)
    for name in ("model", "mobile_body", "fixed_body", "motion"):
        if not tab.has(name):
            raise tab.error(name, f"missing '{name}'", "model, mobile_body, fixed_body and motion in [opensim]")
    model_file = tab.path("model", "an OpenSim .osim model file")
    motion_file = tab.path("motion", "a .mot or .sto of coordinate values")
    for key, path in (("model", model_file), ("motion", motion_file)):
        if not path.is_file():
            raise tab.error(key, f"file not found: {path}", "an existing file (relative to the scene file)")
    search_path = [scene_file.parent / p for p in (tab.table.get("geometry_path") or [])]
    osim = import_opensim()
    # OpenSim logs "Couldn't find file" for every mesh of every body it cannot find (16 lines for
    # gait2392 with four meshes copied); the two bodies used are looked up by body_surface, which
    # says where it looked. The level goes back to at least warnings: a return to info is itself
    # logged ("Set log level to Info"), as is every model load.
    level = max(osim.Logger.getLevel(), osim.Logger.Level_Warn)
    osim.Logger.setLevel(osim.Logger.Level_Error)
    try:
        model = osim.Model(str(model_file))
    except Exception as exc:  # opensim raises its own exception types from C++
        raise InputError(f"OpenSim cannot read the model: {str(exc).strip().splitlines()[0]}", file=model_file, key=tab.key("model")) from None
    finally:
        osim.Logger.setLevel(level)
    bodies = {}
    for key in ("mobile_body", "fixed_body"):
        name = tab.string(key)
        if not model.getBodySet().contains(name):
            names = [model.getBodySet().get(i).getName() for i in range(model.getBodySet().getSize())]
            raise tab.error(key, f"the model has no body '{name}'", "one of " + ", ".join(names))
        bodies[key] = model.getBodySet().get(name)
    try:
        state = model.initSystem()
    except Exception as exc:  # e.g. a socket naming a frame the model does not have
        raise InputError(f"OpenSim cannot assemble the model: {str(exc).strip().splitlines()[0]}", file=model_file, key=tab.key("model"),
                         expected="a model OpenSim can initialise (every joint's frames and sockets present)") from None
    coordinates, missing, warnings = _motion_coordinates(osim, model, motion_file, time_s, tab.key("motion"))
    coordinate_set = model.getCoordinateSet()
    rotation, translation = np.empty((len(time_s), 3, 3)), np.empty((len(time_s), 3))
    ground_rotation, ground_translation = np.empty((len(time_s), 3, 3)), np.empty((len(time_s), 3))
    for k in range(len(time_s)):
        for name, value in coordinates.items():
            coordinate_set.get(name).setValue(state, float(value[k]), False)
        model.realizePosition(state)
        pose = bodies["fixed_body"].findTransformBetween(state, bodies["mobile_body"])  # X_MF: F in M's frame
        rotation[k], translation[k] = _matrix(pose.R()), _vector(pose.p()) * M_TO_MM
        in_ground = bodies["mobile_body"].getTransformInGround(state)
        ground_rotation[k], ground_translation[k] = _matrix(in_ground.R()), _vector(in_ground.p()) * M_TO_MM
    placed = np.isfinite(rotation).all(axis=(1, 2)) & np.isfinite(translation).all(axis=1) & np.isfinite(ground_rotation).all(axis=(1, 2))
    placed &= np.isfinite(ground_translation).all(axis=1) & (np.abs(translation).max(axis=1) <= MAX_COORDINATE_MM)
    # A joint axis of (0, 1e300, 1) leaves OpenSim's rotation far from orthogonal (a fuzz found it).
    placed &= np.abs(np.einsum("kji,kjl->kil", rotation, rotation) - np.eye(3)).max(axis=(1, 2)) <= 1e-9
    if not placed.all():
        k = int(np.flatnonzero(~placed)[0])
        raise InputError(
            f"at time point {k} (t = {time_s[k]:g} s) the model places '{tab.string('fixed_body')}' in '{tab.string('mobile_body')}' "
            f"at non-finite or farther than {MAX_COORDINATE_MM:g} mm coordinates, or turned by a matrix that is not a rotation",
            file=model_file, key=tab.key("model"),
            expected=f"finite joint and frame parameters in the model and finite coordinates in {motion_file}",
        )
    only = {key: tab.strings(key, len(tab.table[key])) if tab.has(key) else None for key in ("mobile_meshes", "fixed_meshes")}
    mobile = body_surface(osim, model, tab.string("mobile_body"), model_file, search_path, only["mobile_meshes"], tab.key("mobile_body"))
    fixed = body_surface(osim, model, tab.string("fixed_body"), model_file, search_path, only["fixed_meshes"], tab.key("fixed_body"))
    if missing:
        warnings.append(
            f"{motion_file}: {len(missing)} model coordinate(s) are not in the motion and stay at their default values "
            f"({', '.join(missing[:6])}{', ...' if len(missing) > 6 else ''})"
        )
    poses = BodyPoses(rotation, translation, coordinates, ground_rotation, ground_translation)
    return OpenSimBodies(mobile, fixed, poses, tuple(warnings))


def load_in_mobile_frame(load: LoadSeries, poses: BodyPoses) -> LoadSeries:
    """A load expressed in ground (a JointReaction in_ground) re-expressed in M's frame, the scene's:
    F_M = R_GM^T F_G, M_M = R_GM^T M_G, P_M = R_GM^T (P_G - o_M)."""
    from dataclasses import replace

    turn = np.transpose(poses.mobile_in_ground_rotation, (0, 2, 1))
    point = None
    if load.point_mm is not None:
        point = np.einsum("kij,kj->ki", turn, load.point_mm - poses.mobile_in_ground_mm)
    return replace(
        load,
        force_n=np.einsum("kij,kj->ki", turn, load.force_n),
        moment_nmm=np.einsum("kij,kj->ki", turn, load.moment_nmm),
        point_mm=point,
        in_ground=False,
    )


def model_geometry(
    data: dict[str, Any], scene_file: Path, cartilage: Cartilage, load: LoadSeries, notes: list[str]
) -> tuple[TriangleSurface, TriangleSurface, np.ndarray, BodyPoses, LoadSeries]:
    """The scene's geometry, F's poses and the load (re-expressed in M's frame) from `[opensim]`.

    Returns ``(mobile, fixed, reference_point_mm, poses, load)``. The surfaces are oriented
    towards each other with F at its first pose, and checked to lie within reach of h_max there.
    ``[kinematics]`` cannot be combined (the model gives every coordinate), nor `[load] axes`
    other than "same" (the scene is in the model's axes).
    """
    import warnings

    from geometries.repair import check_pair_distance, orient_pair

    file = str(scene_file)
    check_load_bodies(data["load"], data["opensim"], file)
    if "kinematics" in data:
        raise InputError("[kinematics] and [opensim] both place the fixed body", file=file, key="kinematics",
                         expected="one of them: [opensim] takes every coordinate from its motion")
    geometry = SceneTable(data["geometry"], file, "geometry", {"reference_point_mm", "spring_spacing_mm"})
    axes = data["load"].get("axes", "same")
    if axes not in ("same", ["x", "y", "z"]):
        raise InputError(f"axes = {axes!r} in a scene built from an OpenSim model", file=file, key="load.axes",
                         expected='axes = "same": the scene is in the model\'s own axes (M\'s body frame, mm)')
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        bodies = load_opensim_bodies(data["opensim"], scene_file, load.time_s)
        placed = TriangleSurface(bodies.poses.placed_vertices_mm(bodies.fixed, 0), bodies.fixed.triangles, name="fixed", source=bodies.fixed.source)
        mobile, placed = orient_pair(bodies.mobile, placed, mobile_key="opensim.mobile_body", fixed_key="opensim.fixed_body",
                                     near_mm=cartilage.max_spring_length_mm)
        check_pair_distance(mobile, placed, cartilage.max_spring_length_mm, key="opensim")
    notes.extend(str(w.message) for w in caught)
    notes.extend(bodies.warnings)
    fixed = TriangleSurface(bodies.fixed.vertices_mm, placed.triangles, name="fixed", source=bodies.fixed.source)
    if load.in_ground:
        load = load_in_mobile_frame(load, bodies.poses)
    reference = geometry.optional_triple("reference_point_mm")
    if reference is None:
        areas = mobile.areas_mm2
        reference = (mobile.centroids_mm * areas[:, None]).sum(axis=0) / areas.sum()
    return mobile, fixed, np.asarray(reference, float), bodies.poses, load
