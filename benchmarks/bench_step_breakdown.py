"""Where an EDEM step's time goes, next to a bare Embree cast of the same rays (issue 13).

Companion to ``bench_step_vs_cast.py`` (same scenes, sizes and bare cast): every stage of the
step is wrapped in a wall-clock timer, so the medians per time point show what the ratio is made
of. The timers add a few microseconds per call: use ``bench_step_vs_cast.py`` for the ratio
itself. Stages nest: "embree traversal", "float64 re-measure", "miss repair" and "star
re-solves" are parts of "cast()", which is part of "geometry"; "pre-flight" (once per run,
:func:`edem.preflight.preflight`, here per time point) is outside the loop; "other loop work" is
the step's total minus the pre-flight, geometry, the solve and the named helpers. ``--cpu``
times everything by the CPU time of the calling thread (``time.thread_time``: on a loaded
machine the waits for a core drop out).

    PYTHONPATH=. .venv/bin/python benchmarks/bench_step_breakdown.py [--rounds 5] [--quick] [--cpu]
"""

from __future__ import annotations

import argparse
import functools
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import edem.beds as beds  # noqa: E402
import edem.preflight as preflight  # noqa: E402
import edem.raycast as raycast  # noqa: E402
import edem.solver as solver  # noqa: E402
from bench_step_vs_cast import CASES, bare_rays  # noqa: E402
from edem.scene import Scene, load_scene  # noqa: E402

seconds: dict[str, float] = {}
clock = time.perf_counter  # or time.thread_time (--cpu)

# (owner, attribute, label): the stages timed, in the order printed
STAGES = (
    (solver, "preflight", "pre-flight"),
    (solver, "spring_geometry", "geometry"),
    (raycast.RayCaster, "cast_rays", "  cast()"),
    (raycast.RayCaster, "_embree_run", "    embree traversal (all passes)"),
    (raycast.RayCaster, "_remeasure", "    float64 re-measure"),
    (raycast.RayCaster, "_repair_misses", "    miss repair (grid + probes)"),
    (raycast.RayCaster, "_star_hits", "    edge/vertex star re-solves"),
    (beds, "solve_unilateral", "solve_unilateral"),
    (Scene, "fixed_placement", "fixed_placement"),
    (solver, "ligament_elements", "ligament_elements"),
    (solver, "contact_law", "contact_law"),
    (solver, "check_increment", "check_increment"),
)
TOP_LEVEL = ("pre-flight", "geometry", "solve_unilateral", "fixed_placement", "ligament_elements", "contact_law", "check_increment")


def timed(function, label: str):
    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        start = clock()
        try:
            return function(*args, **kwargs)
        finally:
            seconds[label] = seconds.get(label, 0.0) + clock() - start

    return wrapper


def breakdown(name: str, mesh_size_mm: float | None, rounds: int) -> None:
    # the stances as these measurements were made: the thesis's geometry, threshold law and independent springs
    thesis = {"geometry.cartilage": False, "cartilage.law": "threshold", "cartilage.coupling": "none"}
    scene = load_scene(name, thesis if mesh_size_mm is None else {**thesis, "geometry.mesh_size_mm": mesh_size_mm})
    caster = raycast.RayCaster(scene.fixed.vertices_mm, scene.fixed.triangles)
    result = solver.run(scene, "edem", caster=caster)  # warm-up
    h = scene.cartilage.max_spring_length_mm
    rays = [
        (np.ascontiguousarray(o - caster._centre_mm, dtype=np.float32), np.ascontiguousarray(d, dtype=np.float32))
        for o, d in bare_rays(scene, result.steps)
    ]
    per_round = []
    for _ in range(rounds):  # interleaved, so both see the same machine load
        seconds.clear()
        start = clock()
        result = solver.run(scene, "edem", caster=caster)
        step = clock() - start
        start = clock()
        for o, d in rays:
            caster._scene.run(o, d, dists=np.full(len(o), 2.0 * h, np.float32), output=1)
        per_round.append(dict(seconds, step=step, bare=clock() - start))
    n_steps = len(result.steps)
    median = {k: 1e3 * statistics.median(r.get(k, 0.0) for r in per_round) / n_steps for k in per_round[0] | {"bare": 0}}
    other = median["step"] - sum(median.get(k, 0.0) for k in TOP_LEVEL)
    kind = "CPU ms" if clock is time.thread_time else "ms"
    print(f"\n{name} ({result.n_springs} springs x {n_steps} steps), {kind} per time point, median of {rounds}:")
    print(f"  EDEM step {median['step']:8.3f}   bare Embree {median['bare']:7.3f}   ratio {median['step'] / median['bare']:5.2f}x")
    for _, _, label in STAGES:
        print(f"  {label:36s} {median.get(label, 0.0):8.3f}")
    print(f"  {'other loop work':36s} {other:8.3f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--quick", action="store_true", help="only the ~3k-spring cases")
    parser.add_argument("--cpu", action="store_true", help="CPU time of the calling thread instead of the wall clock")
    args = parser.parse_args()
    global clock
    if args.cpu:
        clock = time.thread_time
    for owner, attribute, label in STAGES:
        setattr(owner, attribute, timed(getattr(owner, attribute), label))
    for name, sizes in CASES:
        for size in sizes[:1] if args.quick else sizes:
            breakdown(name, size, args.rounds)


if __name__ == "__main__":
    main()
