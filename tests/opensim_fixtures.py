"""A small OpenSim model built with the opensim API: a tibia welded to ground, a talus on a
CustomJoint with two coordinates (a rotation about z and a slide along x), meshes written by
the project (a cylindrical talar dome under a plate), and a motion."""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path

import numpy as np
from support import cylinder_patch, grid_plate

from geometries.surface import TriangleSurface

JOINT_CENTRE_IN_TIBIA_M = np.array([0.0, -0.4, 0.0])
PLATE_ABOVE_DOME_M = 0.0015  # the tibial plate 1.5 mm above the top of the dome at the neutral pose
TIBIA_MESH_SCALE = 2.0  # the tibia mesh file is written at half size


def dome_in_opensim_axes() -> TriangleSurface:
    """Cylinder R 20 mm, 28 mm long, 114 deg, axis along OpenSim z through (0, -R, 0): top at the
    talus origin, normals outward; in metres. support.cylinder_patch has its axis along x and
    its top up (z): the cyclic map (x, y, z) -> (y, z, x) turns it into OpenSim's axes."""
    dome = cylinder_patch(20.0, 28.0, 114.0, 40, 8)
    v = dome.vertices_mm[:, [1, 2, 0]] / 1000.0
    return TriangleSurface(v, dome.triangles)


def plate_in_opensim_axes() -> TriangleSurface:
    """40 x 40 mm plate facing down (-y), in metres at half size (the model scales it by 2)."""
    plate = grid_plate(40.0, 40.0, 10, facing_up=False)
    v = plate.vertices_mm[:, [1, 2, 0]] / 1000.0 / TIBIA_MESH_SCALE
    return TriangleSurface(v, plate.triangles)


def build_model(folder: Path) -> Path:
    from edem.opensim_model import import_opensim
    from geometries.mesh_files import write_surface

    osim = import_opensim()

    geometry = folder / "Geometry"
    geometry.mkdir(parents=True, exist_ok=True)
    write_surface(geometry / "talus_dome.stl", dome_in_opensim_axes())
    write_surface(geometry / "tibia_plate.stl", plate_in_opensim_axes())
    model = osim.Model()
    model.setName("two_body_ankle")
    tibia = osim.Body("tibia", 1.0, osim.Vec3(0), osim.Inertia(1, 1, 1))
    talus = osim.Body("talus", 0.1, osim.Vec3(0), osim.Inertia(0.01, 0.01, 0.01))
    model.addBody(tibia)
    model.addBody(talus)
    model.addJoint(osim.WeldJoint("ground_tibia", model.getGround(), tibia))
    # CustomJoint(name, parent, ..., SpatialTransform) segfaults in opensim 4.6's Python bindings
    # (opensim-core issue 4166): build it empty and fill in its frames, axes and coordinates.
    joint = osim.CustomJoint()
    joint.setName("ankle")
    parent = osim.PhysicalOffsetFrame("tibia_offset", tibia, osim.Transform(osim.Vec3(*JOINT_CENTRE_IN_TIBIA_M)))
    child = osim.PhysicalOffsetFrame("talus_offset", talus, osim.Transform(osim.Vec3(0)))
    joint.addComponent(parent)
    joint.addComponent(child)
    joint.connectSocket_parent_frame(parent)
    joint.connectSocket_child_frame(child)
    transform = joint.upd_SpatialTransform()
    for axis, name in ((2, "ankle_angle"), (3, "ankle_slide")):  # rotation3 about z, translation1 along x
        transform_axis = transform.updTransformAxis(axis)
        transform_axis.setCoordinateNames(osim.ArrayStr(name, 1))
        transform_axis.set_function(osim.LinearFunction())
    for name in ("ankle_angle", "ankle_slide"):
        coordinate = osim.Coordinate()
        coordinate.setName(name)
        joint.append_coordinates(coordinate)
    model.addJoint(joint)
    talus.attachGeometry(osim.Mesh("talus_dome.stl"))
    # the plate hangs on an offset frame of the tibia just above the dome, scaled by 2
    plate_frame = osim.PhysicalOffsetFrame("plate_frame", tibia, osim.Transform(osim.Vec3(*(JOINT_CENTRE_IN_TIBIA_M + [0.0, PLATE_ABOVE_DOME_M, 0.0]))))
    tibia.addComponent(plate_frame)
    mesh = osim.Mesh("tibia_plate.stl")
    mesh.set_scale_factors(osim.Vec3(TIBIA_MESH_SCALE))
    plate_frame.attachGeometry(mesh)
    model.finalizeConnections()
    path = folder / "two_body_ankle.osim"
    model.printToXML(str(path))
    return path


def write_motion(path: Path, time_s, angle_deg, slide_m) -> Path:
    """An IK-style .mot (inDegrees=yes) with the two coordinates and a column the model lacks."""
    lines = ["Coordinates", "version=1", f"nRows={len(time_s)}", "nColumns=4", "inDegrees=yes", "endheader",
             "time\tankle_angle\tankle_slide\tpelvis_tilt"]
    lines += [f"{t:.6f}\t{a:.10f}\t{s:.10f}\t0.0" for t, a, s in zip(time_s, angle_deg, slide_m)]
    path.write_text("\n".join(lines) + "\n")
    return path


def tibia_pose_in_talus_mm(angle_deg: float, slide_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Closed form of F (tibia) in M (talus): the talus sits in the tibia at R_z(a), p = c + (s, 0, 0)
    (CustomJoint translations are along the parent's axes); invert it."""
    a = np.radians(angle_deg)
    r = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    p = (JOINT_CENTRE_IN_TIBIA_M + [slide_m, 0.0, 0.0]) * 1000.0
    return r.T, -r.T @ p


def add_prescribed_force(model_file: Path, out_file: Path, body: str, force_n: tuple[tuple[float, float], ...],
                         point_m: tuple[float, float, float], end_time_s: float) -> Path:
    """A copy of the model without gravity and with a PrescribedForce on ``body``: its components
    (body frame) ramp linearly from ``force_n[i][0]`` at t = 0 to ``force_n[i][1]`` at ``end_time_s``,
    applied at the fixed ``point_m`` of the body. The only external load, so JointReaction must
    answer with it (quasi-statically: the motion holds the coordinates still)."""
    from edem.opensim_model import import_opensim

    osim = import_opensim()
    model = osim.Model(str(model_file))
    model.setGravity(osim.Vec3(0))

    def ramp(start: float, end: float):
        function = osim.PiecewiseLinearFunction()
        function.addPoint(0.0, start)
        function.addPoint(end_time_s, end)
        return function

    force = osim.PrescribedForce("external_load", model.getBodySet().get(body))
    force.setForceIsInGlobalFrame(False)
    force.setPointIsInGlobalFrame(False)
    force.setForceFunctions(*(ramp(*f) for f in force_n))
    force.setPointFunctions(*(osim.Constant(p) for p in point_m))
    model.addForce(force)
    model.finalizeConnections()
    model.printToXML(str(out_file))
    return out_file


def run_joint_reaction(model_file: Path, motion_file: Path, joint: str, on_body: str, in_frame: str,
                       results_dir: Path, time_range_s: tuple[float, float], external_loads: Path | None = None,
                       forces_file: Path | None = None, lowpass_hz: float = -1.0) -> Path:
    """OpenSim's AnalyzeTool over a motion with JointReaction (applying the actuator forces of
    ``forces_file``, a StaticOptimization result, when given): the ReactionLoads .sto OpenSim wrote."""
    from edem.opensim_model import import_opensim

    osim = import_opensim()
    reaction = osim.JointReaction()
    reaction.setName("JointReaction")
    for setter, value in ((reaction.setJointNames, joint), (reaction.setOnBody, on_body), (reaction.setInFrame, in_frame)):
        names = osim.ArrayStr()
        names.append(value)
        setter(names)
    if forces_file is not None:
        reaction.setForcesFileName(str(forces_file))
    _analyze(osim, "edem_jr", reaction, model_file, motion_file, results_dir, time_range_s, external_loads, lowpass_hz)
    (written,) = results_dir.glob("edem_jr_JointReaction_ReactionLoads.sto")
    return written


def _analyze(osim, name: str, analysis, model_file: Path, motion_file: Path, results_dir: Path,
             time_range_s: tuple[float, float], external_loads: Path | None, lowpass_hz: float) -> None:
    tool = osim.AnalyzeTool()
    tool.setName(name)
    tool.setModelFilename(str(model_file))
    tool.setCoordinatesFileName(str(motion_file))
    tool.setLowpassCutoffFrequency(lowpass_hz)
    tool.setInitialTime(time_range_s[0])
    tool.setFinalTime(time_range_s[1])
    tool.setResultsDir(str(results_dir))
    if external_loads is not None:
        tool.setExternalLoadsFileName(str(external_loads))
    analysis.setStartTime(time_range_s[0])
    analysis.setEndTime(time_range_s[1])
    tool.updAnalysisSet().cloneAndAppend(analysis)
    results_dir.mkdir(parents=True, exist_ok=True)
    setup = results_dir / f"{name}_setup.xml"
    tool.printToXML(str(setup))
    osim.AnalyzeTool(str(setup)).run()  # from its setup file, as OpenSim's GUI and command-line tool run it


#: Public OpenSim data beside the clone (docs: /work/shared/data/opensim-gait2392/README.md there);
#: EDEM_SHARED_DATA points elsewhere (a git worktree is not beside it).
SHARED_DATA = Path(os.environ.get("EDEM_SHARED_DATA", Path(__file__).resolve().parents[1].parent / "shared" / "data"))
GAIT2392 = SHARED_DATA / "opensim-gait2392"


def gait2392_ankle_reaction(folder: Path) -> Path:
    """Static optimisation then JointReaction of ``ankle_r`` on the talus, in the tibia, over the
    right stance of subject01's walk (about 15 s): the worked example's own OpenSim pipeline
    (docs/examples/gait2392_ankle.py, ``ankle_reaction``), so the test and the example run the same analysis."""
    spec = importlib.util.spec_from_file_location("gait2392_ankle", Path(__file__).resolve().parents[1] / "docs" / "examples" / "gait2392_ankle.py")
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    return example.ankle_reaction(GAIT2392, folder)
