"""The result directory of SPEC 9: summary.json, timeseries.csv, pressure.pvd + one .vtp per step."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from edem.atomic_dirs import atomic_result_dir
from edem.solver import RunResult
from geometries.mesh_io import write_vtp

TIMESERIES_COLUMNS = (
    "step",
    "time_s",
    "force_x_n",
    "force_y_n",
    "force_z_n",
    "peak_pressure_mpa",
    "mean_pressure_mpa",
    "contact_area_mm2",
    "disp_x_mm",
    "disp_y_mm",
    "disp_z_mm",
    "rot_x_rad",
    "rot_y_rad",
    "rot_z_rad",
    "iterations",
    "force_residual_n",
)


def summary(run: RunResult) -> dict:
    """The summary.json content (SPEC 9 keys, plus the law and the moment residual)."""
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
    }


def timeseries_rows(run: RunResult) -> list[list[float]]:
    return [
        [
            s.step,
            s.time_s,
            *s.force_n,
            s.peak_pressure_mpa,
            s.mean_pressure_mpa,
            s.contact_area_mm2,
            *s.displacement_mm,
            *s.rotation_rad,
            s.iterations,
            s.force_residual_n,
        ]
        for s in run.steps
    ]


def write_results(run: RunResult, out_dir: str | Path, *, overwrite: bool = False) -> Path:
    """Write the SPEC 9 result directory for a DEM/EDEM run, atomically and sealed with its
    manifest (:mod:`edem.atomic_dirs`; ``overwrite`` replaces an existing result); returns it."""
    with atomic_result_dir(out_dir, overwrite=overwrite) as tmp:
        write_result_files(run, tmp)
    return Path(out_dir)


def write_result_files(run: RunResult, out: Path) -> None:
    """The files of :func:`write_results` into the existing directory ``out`` (not sealed)."""
    data = summary(run)
    _check_finite(data)
    (out / "summary.json").write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    with open(out / "timeseries.csv", "w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow(TIMESERIES_COLUMNS)
        for row in timeseries_rows(run):
            writer.writerow([_fmt(x) for x in row])
    _write_pressure_maps(run, out)


def _fmt(x: float) -> str:
    return str(int(x)) if isinstance(x, (int, np.integer)) else repr(float(x))


def _check_finite(data: dict) -> None:
    for key, value in data.items():
        values = value if isinstance(value, list) else [value]
        if any(isinstance(v, float) and not math.isfinite(v) for v in values):
            raise ValueError(f"summary value {key} is not finite: {value}")


def _write_pressure_maps(run: RunResult, out: Path) -> None:
    """pressure.pvd + pressure_NNNN.vtp: the mobile surface at each step's pose (ParaView).

    Cell data: pressure_mpa, spring_length_mm (0 where the ray found nothing: see ray_hit),
    in_contact and ray_hit (0/1). Degenerate triangles carry no spring: 0 everywhere.
    """
    scene = run.scene
    triangles = scene.mobile.triangles
    spring_triangle = scene.spring_triangle
    n_tri = triangles.shape[0]
    entries = []
    for s in run.steps:
        points = s.mobile_placement.points(scene.mobile.vertices_mm)
        pressure = np.zeros(n_tri)
        pressure[spring_triangle] = s.pressure_mpa
        hit = np.isfinite(s.spring_length_mm)
        length = np.zeros(n_tri)
        length[spring_triangle] = np.where(hit, s.spring_length_mm, 0.0)
        ray_hit = np.zeros(n_tri, np.int8)
        ray_hit[spring_triangle] = hit
        contact = np.zeros(n_tri, np.int8)
        contact[spring_triangle] = s.in_contact
        name = f"pressure_{s.step:04d}.vtp"
        write_vtp(
            out / name,
            points,
            triangles,
            {"pressure_mpa": pressure, "spring_length_mm": length, "in_contact": contact, "ray_hit": ray_hit},
        )
        entries.append((s.time_s, name))
    write_pvd(out / "pressure.pvd", entries)
    write_vtp(out / "fixed.vtp", scene.fixed.vertices_mm, scene.fixed.triangles, {})


def write_pvd(path: Path, entries: list[tuple[float, str]]) -> None:
    """A ParaView collection file listing one dataset per time value."""
    lines = ['<?xml version="1.0"?>', '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">', "  <Collection>"]
    lines += [f'    <DataSet timestep="{t!r}" part="0" file={quoteattr(name)}/>' for t, name in entries]
    lines += ["  </Collection>", "</VTKFile>", ""]
    path.write_text("\n".join(lines), encoding="utf-8")
