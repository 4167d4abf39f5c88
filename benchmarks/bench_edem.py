"""EDEM stance-like benchmark (issue: 3k springs x 65 steps <= 0.1 s; 30k springs x 100 steps <= 1.5 s).

The idealised ankle with a tibia rotating about the ankle axis from 0 to 16.31 deg and a load
ramping from 50 N to 4190 N: every step redoes the geometry (ray casting) and the unilateral
solve. Prints the median of 5 runs of the solver alone (geometry built and Embree scene created
once beforehand, as a gait study would), with the share of ray casting vs assembly and solve.

    .venv/bin/python benchmarks/bench_edem.py
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from edem.loads import JointKinematics
from edem.raycast import RayCaster
from edem.scene import Scene
from edem.solver import run
from geometries.builders import build_geometry


def stance_like_scene(mesh_size_mm: float, n_steps: int, **cartilage) -> Scene:
    """The idealised ankle's stance; ``cartilage``: Scene.from_arrays's cartilage keys beyond E and nu."""
    geometry = build_geometry("ideal_ankle", {"mesh_size_mm": mesh_size_mm, "cartilage": False})  # the thesis's cylinder under a plane
    t = np.linspace(0.0, 0.64, n_steps)
    s = t / t[-1]
    force = np.column_stack([60.0 * s, -40.0 * np.sin(np.pi * s), 50.0 + 4140.0 * s])
    return Scene.from_arrays(
        geometry.mobile.vertices_mm, geometry.mobile.triangles, geometry.fixed.vertices_mm, geometry.fixed.triangles, force,
        youngs_modulus_mpa=10.35, poissons_ratio=0.42, time_s=t, load_frame="fixed", fixed_dofs=("tx", "rx", "ry", "rz"),
        kinematics=JointKinematics(geometry.ankle_axis_point_mm, geometry.ankle_axis_direction, np.radians(16.31) * s),
        name=f"stance-like-{geometry.mobile.n_triangles}", description="benchmark", **cartilage,
    )


def bench(mesh_size_mm: float, n_steps: int, target_s: float, rounds: int = 5) -> None:
    scene = stance_like_scene(mesh_size_mm, n_steps)
    caster = RayCaster(scene.fixed.vertices_mm, scene.fixed.triangles)
    run(scene, "edem", caster=caster)  # warm-up: imports, first Embree traversal
    totals, geometry, solve = [], [], []
    for _ in range(rounds):
        result = run(scene, "edem", caster=caster)
        totals.append(result.wall_time_s)
        geometry.append(result.seconds["geometry"])
        solve.append(result.seconds["solve"])
    total = statistics.median(totals)
    share = statistics.median(geometry) / (statistics.median(geometry) + statistics.median(solve))
    last = result.steps[-1]
    print(
        f"{result.n_springs:6d} springs x {n_steps:3d} steps: total {total:.3f} s (median of {rounds}; "
        f"target <= {target_s} s: {'met' if total <= target_s else 'MISSED'}), {1e3 * total / n_steps:.2f} ms/step, "
        f"ray casting {100 * share:.0f} % / assembly+solve {100 * (1 - share):.0f} %; "
        f"final peak {last.peak_pressure_mpa:.2f} MPa, area {last.contact_area_mm2:.0f} mm^2, "
        f"mean iterations {np.mean([s.iterations for s in result.steps]):.1f}"
    )


if __name__ == "__main__":
    bench(0.94, 65, 0.1)
    bench(0.3, 100, 1.5)
