"""EDEM step vs a bare Embree cast of the same rays (issue 23: <= 3x the cast at >= 10k springs, <= 5x at 3k).

For each built-in stance scene (the idealised ankle and the subject-like ankle) at ~3k, ~10k and
~30k springs, one run measures in the same process, median of several rounds:

* the EDEM solver alone (``edem.solver.run`` with the Embree scene built beforehand, as a gait
  study would), per time point;
* one bare embreex traversal per time point of exactly the rays that step casts (M's springs at
  the pose the step starts from, moved into F's frame, over the signed window), with no float64
  re-measure, no repairs and no solve: the floor the step is compared with.

``--floor`` also times a skeleton step in the solver's numpy idiom: only what no step can skip
(rays into F's frame, the Embree pass, the float64 plane distance of the hits, the candidates,
their rows turned with M, one Newton iteration on the 6 DOFs, the pressure scattered over the
springs), with no edge or miss repair, no line search, no EDEM push-back and no checks. Where
the skeleton alone is near 3x the bare cast, numpy cannot give a full step within 3x.

Absolute times vary 2-3x between runs on a shared machine; the ratio is measured in one run.
Each case is timed twice over: by the wall clock (the goal's figure, on a quiet machine) and by
the CPU time of the calling thread (``time.thread_time``: the step and the Embree traversal both
run on it, so the waits for a core that a loaded machine adds to the wall clock drop out).
The last lines are the ratios as a table against the goal.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_step_vs_cast.py [--rounds 5] [--quick | --sweep | --floor]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from edem.mechanics import generalised_directions  # noqa: E402
from edem.raycast import RayCaster  # noqa: E402
from geometries.rowwise import row_dot, rows_times  # noqa: E402
from edem.scene import load_scene  # noqa: E402
from edem.solver import run  # noqa: E402
from edem.springs import Placement  # noqa: E402

# (scene, mesh sizes giving ~3k, ~10k and ~30k springs); sizes measured on the built-in builders.
CASES = (("ideal-stance", (0.94, 0.5, 0.3)), ("subject-stance", (None, 0.45, 0.3)))
#: the stances as these measurements were made: the thesis's geometry, threshold law and
#: independent springs (the scenes' default is now the gap law on both cartilage layers, coupled)
THESIS_STANCE = {"geometry.cartilage": False, "cartilage.law": "threshold", "cartilage.coupling": "none"}


def target_ratio(n_springs: int) -> float:
    """Issue 23: per-call overhead, not work, dominates a step below 10k springs."""
    return 3.0 if n_springs >= 10_000 else 5.0


def bare_rays(scene, steps) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per time point: float32 origins (window start) and directions in F's frame, as Embree sees them."""
    h = scene.cartilage.max_spring_length_mm
    poses = [Placement.identity(scene.reference_point_mm)] + [s.mobile_placement for s in steps[:-1]]
    rays = []
    for k, pose in enumerate(poses):
        rotation, translation = scene.fixed_placement(k).affine()
        origins = (pose.points(scene.spring_centroid_mm) - translation) @ rotation
        directions = pose.vectors(scene.spring_normal) @ rotation
        rays.append((origins - h * directions, directions))
    return rays


def bench(name: str, mesh_size_mm: float | None, rounds: int) -> tuple[int, float, float, float]:
    """Prints and returns (springs, EDEM s per step, bare cast s per step, ratio of CPU times)."""
    overrides = dict(THESIS_STANCE) if mesh_size_mm is None else {**THESIS_STANCE, "geometry.mesh_size_mm": mesh_size_mm}
    scene = load_scene(name, overrides)
    caster = RayCaster(scene.fixed.vertices_mm, scene.fixed.triangles)
    result = run(scene, "edem", caster=caster)  # warm-up
    h = scene.cartilage.max_spring_length_mm
    rays = [
        (np.ascontiguousarray(o - caster._centre_mm, dtype=np.float32), np.ascontiguousarray(d, dtype=np.float32))
        for o, d in bare_rays(scene, result.steps)
    ]

    def bare_pass() -> tuple[float, float]:
        start, start_cpu = time.perf_counter(), time.thread_time()
        for o, d in rays:
            caster._scene.run(o, d, dists=np.full(len(o), 2.0 * h, np.float32), output=1)
        return time.perf_counter() - start, time.thread_time() - start_cpu

    step_times, cast_times, geometry_times, step_cpu, cast_cpu = [], [], [], [], []
    for _ in range(rounds):  # interleaved, so both see the same machine load
        start_cpu = time.thread_time()
        result = run(scene, "edem", caster=caster)
        step_cpu.append(time.thread_time() - start_cpu)
        step_times.append(result.wall_time_s)
        geometry_times.append(result.seconds["geometry"])
        wall, cpu = bare_pass()
        cast_times.append(wall)
        cast_cpu.append(cpu)
    n_steps = len(result.steps)
    step, cast, geometry = (statistics.median(x) / n_steps for x in (step_times, cast_times, geometry_times))
    ratio, target = step / cast, target_ratio(result.n_springs)
    cpu_ratio = statistics.median(step_cpu) / statistics.median(cast_cpu)
    print(
        f"{name:15s} {result.n_springs:7d} springs x {n_steps:3d} steps: EDEM {1e3 * step:7.3f} ms/step "
        f"(geometry {1e3 * geometry:6.3f}), bare Embree {1e3 * cast:6.3f} ms/step, "
        f"ratio {ratio:5.2f}x (CPU time {cpu_ratio:5.2f}x; target <= {target:g}x: {'met' if ratio <= target else 'MISSED'})"
    )
    return result.n_springs, step, cast, cpu_ratio


def skeleton_step_s(scene, caster: RayCaster, steps) -> float:
    """Seconds per time point of the skeleton step (module docstring) over the run's poses and loads."""
    h = scene.cartilage.max_spring_length_mm
    rays = caster.prepare(scene.spring_centroid_mm, scene.spring_normal)
    reference_rows = generalised_directions(scene.spring_centroid_mm, scene.spring_normal, scene.reference_point_mm)
    area = scene.spring_area_mm2
    modulus = scene.cartilage.confined_modulus_mpa
    poses = [Placement.identity(scene.reference_point_mm)] + [s.mobile_placement for s in steps[:-1]]
    fixed = [scene.fixed_placement(k) for k in range(len(steps))]
    loads = [np.concatenate([s.force_n, s.moment_nmm]) for s in steps]
    start = time.perf_counter()
    for pose, f_pose, load in zip(poses, fixed, loads):
        (rotation_m, offset_m), (rotation_f, offset_f) = pose.affine(), f_pose.affine()
        rotation = rotation_m.T @ rotation_f
        affine = np.empty((4, 3))
        affine[:3] = rotation
        affine[3] = -((rotation_m.T @ (offset_f - offset_m)) @ rotation + caster._centre_mm)
        origins, directions = rows_times(rays.homogeneous_origins, affine), rows_times(rays.directions, rotation)
        starts = directions * -h
        starts += origins
        ray = caster._embree_run(starts, directions, np.full(len(origins), 2.0 * h, np.float32))
        hit = np.flatnonzero(ray["primID"] >= 0)
        plane = np.take(caster._plane_columns, np.take(ray["primID"], hit), axis=1).T
        length = (plane[:, 3] - row_dot(plane[:, :3], np.take(origins, hit, axis=0))) / row_dot(plane[:, :3], np.take(directions, hit, axis=0))
        inside = length <= h
        candidate, length = hit[inside], length[inside]
        turn = np.zeros((6, 6))
        turn[:3, :3] = turn[3:, 3:] = pose.rotation.T
        columns = np.ascontiguousarray(rows_times(np.take(reference_rows, candidate, axis=0), turn).T)
        stiffness = modulus * area[candidate] / length
        u = np.linalg.solve(np.einsum("ik,jk->ij", columns * stiffness, columns), load)
        force = stiffness * np.einsum("i,ij->j", u, columns)
        pressure = np.zeros(area.size)
        pressure[candidate] = np.maximum(force, 0.0) / area[candidate]
    return (time.perf_counter() - start) / len(steps)


def floor(name: str, mesh_size_mm: float | None, rounds: int) -> None:
    """Prints the skeleton step and the bare cast per time point, medians of interleaved rounds."""
    scene = load_scene(name, dict(THESIS_STANCE) if mesh_size_mm is None else {**THESIS_STANCE, "geometry.mesh_size_mm": mesh_size_mm})
    caster = RayCaster(scene.fixed.vertices_mm, scene.fixed.triangles)
    steps = run(scene, "edem", caster=caster).steps
    h = scene.cartilage.max_spring_length_mm
    rays = [(np.ascontiguousarray(o - caster._centre_mm, dtype=np.float32), np.ascontiguousarray(d, dtype=np.float32)) for o, d in bare_rays(scene, steps)]
    skeleton, cast = [], []
    for _ in range(rounds):
        skeleton.append(skeleton_step_s(scene, caster, steps))
        begin = time.perf_counter()
        for o, d in rays:
            caster._scene.run(o, d, dists=np.full(len(o), 2.0 * h, np.float32), output=1)
        cast.append((time.perf_counter() - begin) / len(steps))
    a, b = statistics.median(skeleton), statistics.median(cast)
    print(f"{name:15s} {len(scene.spring_area_mm2):7d} springs: skeleton step {1e3 * a:7.3f} ms, bare Embree {1e3 * b:6.3f} ms, ratio {a / b:5.2f}x")


def sweep(name: str, sizes_mm: tuple[float, ...], rounds: int) -> None:
    """Step and cast over the spring count: the least-squares lines t = a + b n say how much of a
    step does not grow with the springs (Python and numpy call overhead) against the cast's."""
    n, step, cast, _ = np.array([bench(name, size, rounds) for size in sizes_mm]).T
    (b_step, a_step), (b_cast, a_cast) = np.polyfit(n, step, 1), np.polyfit(n, cast, 1)
    at_3k = a_cast + b_cast * 3000.0
    print(f"{name}: EDEM step {1e3 * a_step:.3f} ms + {1e6 * b_step:.4f} us/spring, bare cast {1e3 * a_cast:.3f} ms + {1e6 * b_cast:.4f} us/spring; "
          f"the step's fixed part alone is {a_step / at_3k:.2f}x the bare cast at 3k springs, its per-spring part {b_step / b_cast:.2f}x the cast's")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--quick", action="store_true", help="only the ~3k-spring cases")
    parser.add_argument("--scenes", default="ideal-stance,subject-stance")
    parser.add_argument("--floor", action="store_true", help="also the skeleton step (module docstring) against the bare cast")
    parser.add_argument("--sweep", action="store_true", help="the ideal ankle over seven spring counts (348-28862), fitted as a fixed plus a per-spring part")
    args = parser.parse_args()
    print(f"median of {args.rounds} rounds, per time point; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    if args.sweep:
        sweep("ideal-stance", (3.0, 2.0, 1.4, 0.94, 0.6, 0.4, 0.3), args.rounds)
        return
    table = []
    for name, sizes in CASES:
        if name not in args.scenes.split(","):
            continue
        for size in sizes[:1] if args.quick else sizes:
            n_springs, step, cast, cpu_ratio = bench(name, size, args.rounds)
            table.append((name, n_springs, step / cast, cpu_ratio))
            if args.floor:
                floor(name, size, args.rounds)
    print(f"\ngoal (issue 23): EDEM step <= 3x the bare cast at >= 10k springs, <= 5x at 3k; load average now {os.getloadavg()[0]:.1f}")
    print(f"{'scene':15s} {'springs':>7s} {'goal':>5s} {'wall':>6s} {'CPU':>6s}")
    for name, n_springs, ratio, cpu_ratio in table:
        print(f"{name:15s} {n_springs:7d} {target_ratio(n_springs):4g}x {ratio:5.2f}x {cpu_ratio:5.2f}x")


if __name__ == "__main__":
    main()
