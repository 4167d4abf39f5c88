"""A DEM/EDEM run as a result directory (:mod:`edem.resultdir` owns the format)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from edem.loads import JointKinematics
from edem.opensim_model import BodyPoses
from edem.resultdir import TIMESERIES_COLUMNS, Frame, Provenance, SurfaceFrame, timeseries_row, write_pvd, write_result_dir
from edem.solver import RunResult, StepResult

__all__ = ["TIMESERIES_COLUMNS", "summary", "timeseries_rows", "pressure_frame", "write_pvd", "write_results"]


def summary(run: RunResult) -> dict:
    """The summary.json content (the common keys, plus the law and the moment residual)."""
    steps = run.steps
    last = steps[-1]
    return {
        "scene": run.scene.name,
        "method": run.method,
        "steps": len(steps),
        "n_springs": run.n_springs,
        "wall_time_s": run.wall_time_s,
        "peak_pressure_mpa": max(s.peak_pressure_mpa for s in steps),
        "max_contact_area_mm2": max(s.contact_area_mm2 for s in steps),
        "final_displacement_mm": [float(x) for x in last.displacement_mm],
        "final_rotation_rad": [float(x) for x in last.rotation_rad],
        "max_force_residual_n": max(s.force_residual_n for s in steps),
        "max_moment_residual_nmm": max(s.moment_residual_nmm for s in steps),
        "law": run.scene.cartilage.law,
        "warnings": list(run.scene.warnings) + list(run.warnings),
        **({} if run.preflight is None else {"preflight": run.preflight.as_dict()}),
    }


def timeseries_rows(run: RunResult) -> list[dict[str, float]]:
    """One timeseries.csv row per time point of the run: the common columns, then the joint's
    pose (joint_angle_deg, or coord_<name> of an OpenSim model in rad or m), the contact resultant
    sum p A n (N) and its moment about G (N mm), the centre of pressure (mm; G when nothing is in
    contact) and each ligament's tension (N); DEM adds remeasured_imbalance (edem.consistency).
    n points from M to F: the resultant is the load the contact carries, which balances the
    applied load with the ligaments and the constraints."""
    rows = []
    kinematics = run.scene.kinematics
    for s in run.steps:
        row = timeseries_row(s.step, s.time_s, s.force_n, s.peak_pressure_mpa, s.mean_pressure_mpa, s.contact_area_mm2,
                             s.displacement_mm, s.rotation_rad, s.iterations, s.force_residual_n)
        if isinstance(kinematics, JointKinematics):
            row["joint_angle_deg"] = float(np.degrees(kinematics.angle_rad[s.step]))
        elif isinstance(kinematics, BodyPoses):
            row.update({f"coord_{name}": float(values[s.step]) for name, values in kinematics.coordinates.items()})
        row.update(zip(("contact_force_x_n", "contact_force_y_n", "contact_force_z_n"), s.contact_force_n))
        row.update(zip(("contact_moment_x_nmm", "contact_moment_y_nmm", "contact_moment_z_nmm"), s.contact_moment_nmm))
        row.update(zip(("cop_x_mm", "cop_y_mm", "cop_z_mm"), s.centre_of_pressure_mm))
        row.update({f"ligament_{lig.name}_n": float(f) for lig, f in zip(run.scene.ligaments, np.maximum(s.ligament_force_n, 0.0))})
        if s.remeasured_imbalance is not None:
            row["remeasured_imbalance"] = float(s.remeasured_imbalance)
        rows.append(row)
    return rows


def pressure_frame(run: RunResult, s: StepResult) -> Frame:
    """The mobile surface at the step's pose with cell data pressure_mpa, spring_length_mm (0
    where the ray found nothing: see ray_hit), in_contact and ray_hit (0/1). Degenerate triangles
    carry no spring: 0 everywhere."""
    scene = run.scene
    spring_triangle = scene.spring_triangle
    n_tri = scene.mobile.triangles.shape[0]
    pressure = np.zeros(n_tri)
    pressure[spring_triangle] = s.pressure_mpa
    hit = np.isfinite(s.spring_length_mm)
    length = np.zeros(n_tri)
    length[spring_triangle] = np.where(hit, s.spring_length_mm, 0.0)
    ray_hit = np.zeros(n_tri, np.int8)
    ray_hit[spring_triangle] = hit
    contact = np.zeros(n_tri, np.int8)
    contact[spring_triangle] = s.in_contact
    points = s.mobile_placement.points(scene.mobile.vertices_mm)
    cells = {"pressure_mpa": pressure, "spring_length_mm": length, "in_contact": contact, "ray_hit": ray_hit}
    return Frame(s.step, s.time_s, SurfaceFrame(points, scene.mobile.triangles, {}, cells))


def write_results(run: RunResult, out_dir: str | Path, *, frame_steps: list[int] | None = None, note: str | None = None,
                  overwrite: bool = False, provenance: Provenance | None = None, durable: bool = True,
                  time_series_only: bool = False) -> Path:
    """Write the result directory of a DEM/EDEM run (layout: :mod:`edem.resultdir`), atomically.

    Parameters
    ----------
    run : RunResult
        From :func:`edem.solver.solve`.
    out_dir : str or Path
        The directory: summary.json, timeseries.csv, pressure.pvd with one pressure_NNNN.vtp
        per time point (the mobile surface at its pose, cell data ``pressure_mpa`` in MPa,
        ``spring_length_mm``, ``in_contact``, ``ray_hit``), fixed.vtp, fixed.pvd with one
        fixed_NNNN.vtp per written time point, timeseries.sto and manifest.json listing them all.
        Written into a hidden sibling and renamed into place when complete.
    frame_steps : list of int, optional
        Positions in ``run.steps`` whose pressure maps are written (default: all).
    note : str, optional
        Recorded as the summary's "frames" entry when only some maps are written.
    overwrite : bool, optional
        Replace an existing result directory (default: refuse).
    provenance : Provenance, optional
        The resolved scene and the summary's provenance keys (:func:`edem.resultdir.provenance`),
        written in the same atomic step as the rest.
    durable : bool, optional
        Flush every file to disk before the directory is renamed into place (default). False
        for a campaign's case results, a cache verified before use (:mod:`edem.atomic_dirs`).
    time_series_only : bool, optional
        Write no surface (no pressure map, no fixed body) and no timeseries.sto, all optional in
        the format: summary.json, scene.toml, timeseries.csv and an empty pressure.pvd, for
        campaigns of hundreds of runs whose metrics read the time series only.

    Returns
    -------
    Path
        ``out_dir``.

    Raises
    ------
    SolverError
        When a value to write is not finite (naming the file and key).
    InputError
        When ``out_dir`` holds a result already (without ``overwrite``) or is not a result
        directory; ResultWriteError (an InputError) when the disk is full or not writable.
    """
    data = summary(run)
    if note is not None:
        data["frames"] = note
    chosen = [] if time_series_only else range(len(run.steps)) if frame_steps is None else frame_steps
    frames = [pressure_frame(run, run.steps[k]) for k in chosen]
    fixed = None if time_series_only else SurfaceFrame(run.scene.fixed.vertices_mm, run.scene.fixed.triangles)
    return write_result_dir(out_dir, data, timeseries_rows(run), frames, fixed,
                            fixed_frames=[fixed_frame(run, run.steps[k]) for k in chosen], opensim_sto=not time_series_only,
                            overwrite=overwrite, provenance=provenance, durable=durable)


def fixed_frame(run: RunResult, s: StepResult) -> Frame:
    """The fixed body placed where the step's kinematics put it (scene axes, mm)."""
    fixed = run.scene.fixed
    return Frame(s.step, s.time_s, SurfaceFrame(s.fixed_placement.points(fixed.vertices_mm), fixed.triangles))
