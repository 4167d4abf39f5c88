"""The FE's iterative path against its direct one, in one run (docs/method.md, section 6, "The
iterative path"): each case is `edem fe` in a subprocess (its wall time, peak resident memory from
wait4, and summary.json).

1. At ``--coarse`` mm, P2: the direct (MUMPS LU) and the iterative path, their wall times (goal:
   iterative <= 1/2 of direct) and the answer's difference (the bone's displacement, the
   regularised peak, the contact area on M; goal <= 0.5 %).
2. The iterative path at ``--fine`` mm: peak memory (goal <= 3 GB) and wall time against the coarse
   one scaled by the unknowns' ratio (goal <= 1.5: cost linear in the unknowns).
3. Taylor-Hood at nu ``--th-nu``: the Krylov iterations of each Newton step at ``--th-levels`` (goal:
   the per-step mean varies by < 30 % over the levels).
4. With ``--mpi``: ``mpiexec -n 2`` of the iterative path at ``--fine`` mm against case 2 (goal:
   >= 1.5x faster, the same answer to 0.1 %).

The direct path at the fine level is not run (0.7 mm: 11 GB before this path existed).

    PYTHONPATH=$PWD .venv/bin/python benchmarks/bench_fe_iterative.py [--scene subject-standing]
        [--coarse 1.0] [--fine 0.7] [--th-levels 2.0,1.0,0.7] [--th-nu 0.4999] [--skip ...] [--mpi]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def run_fe(root: Path, name: str, scene: str, mesh_mm: float, solver: str, sets: tuple[str, ...] = (),
           ranks: int = 1) -> dict | None:
    """One `edem fe` run; its summary.json with the whole run's ``run_wall_s``, ``run_cpu_s`` (all
    ranks) and ``run_peak_gb`` (the child's peak resident memory; with MPI the largest rank's), or
    None (exit status and last error line printed)."""
    out = root / name
    cmd = [sys.executable, "-m", "edem", "fe", scene, "--degree", "2", "--mesh-size", str(mesh_mm),
           "--linear-solver", solver, "--out", str(out), "--overwrite", "--no-progress"]
    for item in sets:
        cmd += ["--set", item]
    if ranks > 1:  # the MPI of the Python environment's mpi4py, beside its interpreter
        launcher = Path(sys.executable).with_name("mpiexec")
        cmd = [str(launcher) if launcher.exists() else shutil.which("mpiexec") or "mpiexec", "-n", str(ranks), *cmd]
    start = time.perf_counter()
    with open(root / f"{name}.err", "w+") as errors:
        child = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=errors)
        _, status, usage = os.wait4(child.pid, 0)  # ru_maxrss: the largest of the waited process tree, kB
        wall = time.perf_counter() - start
        code = os.waitstatus_to_exitcode(status)
        errors.seek(0)
        err = errors.read().strip()
    if code != 0:
        print(f"  {name}: exit {code} after {wall:.0f} s: {err.splitlines()[-1] if err else ''}")
        return None
    summary = json.loads((out / "summary.json").read_text())
    summary["run_wall_s"], summary["run_peak_gb"] = wall, usage.ru_maxrss / 1e6
    summary["run_cpu_s"] = usage.ru_utime + usage.ru_stime  # steadier than the wall time on a shared machine
    return summary


def answer(summary: dict) -> dict[str, float]:
    """The compared quantities of a run."""
    return {"displacement_mm": float(np.linalg.norm(summary["final_displacement_mm"])),
            "regularised_peak_mpa": float(summary["regularised_peak_pressure_mpa"]),
            "area_on_m_mm2": float(summary["max_contact_area_on_mobile_mm2"])}


def describe(name: str, summary: dict) -> str:
    memory = summary.get("peak_memory_mb")
    return (f"  {name}: {summary['n_dofs']:,} DOFs, whole run {summary['run_wall_s']:.1f} s (solve "
            f"{summary['wall_time_s']:.1f} s; CPU {summary['run_cpu_s']:.1f} s), peak {summary['run_peak_gb']:.2f} GB (summary "
            f"{'-' if memory is None else f'{memory / 1e3:.2f}'} GB), Newton "
            f"{summary['newton_iterations_per_time_point']}, Krylov per Newton step "
            f"{summary['krylov_iterations_per_newton_step']}; "
            + ", ".join(f"{k} {v:.5g}" for k, v in answer(summary).items()))


def differences(a: dict, b: dict) -> str:
    """Relative differences of b's answer from a's, %."""
    x, y = answer(a), answer(b)
    return ", ".join(f"{k} {100.0 * (y[k] - x[k]) / x[k]:+.1e} %" for k in x)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="subject-standing")
    parser.add_argument("--coarse", type=float, default=1.0, help="mesh size of case 1, mm")
    parser.add_argument("--fine", type=float, default=0.7, help="mesh size of cases 2 and 4, mm")
    parser.add_argument("--th-levels", default="2.0,1.0,0.7", help="mesh sizes of case 3, mm")
    parser.add_argument("--th-nu", type=float, default=0.4999, help="Poisson's ratio of case 3")
    parser.add_argument("--skip", default="", help="cases to skip, e.g. 2,3")
    parser.add_argument("--mpi", action="store_true", help="run case 4 (mpiexec -n 2)")
    parser.add_argument("--sets", action="append", default=[], help="--set KEY=VALUE for every run")
    args = parser.parse_args()
    skip = {int(c) for c in args.skip.split(",") if c}
    sets = tuple(args.sets)
    print(f"{args.scene}, P2 (Taylor-Hood in case 3), {os.cpu_count()} CPUs, load average "
          f"{os.getloadavg()[0]:.1f} at the start")
    with tempfile.TemporaryDirectory(prefix="bench_fe_iterative_") as tmp:
        root = Path(tmp)
        coarse = None
        if 1 not in skip or 2 not in skip:
            coarse = run_fe(root, "iterative-coarse", args.scene, args.coarse, "iterative", sets)
        if 1 not in skip:
            print(f"1. {args.coarse} mm, direct against iterative")
            direct = run_fe(root, "direct-coarse", args.scene, args.coarse, "direct", sets)
            for name, summary in (("direct", direct), ("iterative", coarse)):
                if summary:
                    print(describe(name, summary))
            if direct and coarse:
                print(f"  time iterative / direct: whole run {coarse['run_wall_s'] / direct['run_wall_s']:.2f} "
                      f"(CPU {coarse['run_cpu_s'] / direct['run_cpu_s']:.2f}), solve "
                      f"{coarse['wall_time_s'] / direct['wall_time_s']:.2f} (goal <= 0.5); "
                      f"iterative - direct: {differences(direct, coarse)} (goal within 0.5 %)")
        fine = None
        if 2 not in skip:
            print(f"2. the iterative path at {args.fine} mm against {args.coarse} mm")
            fine = run_fe(root, "iterative-fine", args.scene, args.fine, "iterative", sets)
            if coarse and 1 in skip:
                print(describe("coarse", coarse))
            if fine:
                print(describe("fine", fine))
            if fine and coarse:
                ratio = fine["n_dofs"] / coarse["n_dofs"]
                cost = {key: fine[key] / coarse[key] for key in ("wall_time_s", "run_wall_s", "run_cpu_s")}
                print(f"  unknowns x{ratio:.2f}; solve time x{cost['wall_time_s']:.2f}, whole run "
                      f"x{cost['run_wall_s']:.2f}, CPU x{cost['run_cpu_s']:.2f}: "
                      + " / ".join(f"{c / ratio:.2f}" for c in cost.values()) + " of linear (goal <= 1.5); "
                      f"peak {fine['run_peak_gb']:.2f} GB (goal <= 3); {args.fine} - {args.coarse} mm: "
                      f"{differences(coarse, fine)}")
        if 3 not in skip:
            print(f"3. Taylor-Hood at nu {args.th_nu}, iterative")
            means = []
            for level in (float(v) for v in args.th_levels.split(",")):
                th = run_fe(root, f"th-{level}", args.scene, level, "iterative",
                            (*sets, f"cartilage.poissons_ratio={args.th_nu}"))
                if th:
                    print(describe(f"{level} mm", th))
                    steps = [n for point in th["krylov_iterations_per_newton_step"] for n in point]
                    means.append(float(np.mean(steps)))
            if len(means) > 1:
                print(f"  mean Krylov iterations per Newton step {[round(m, 1) for m in means]}: spread "
                      f"{100.0 * (max(means) - min(means)) / min(means):.0f} % (goal < 30 %)")
        if args.mpi:
            print(f"4. mpiexec -n 2, the iterative path at {args.fine} mm")
            parallel = run_fe(root, "iterative-fine-mpi", args.scene, args.fine, "iterative", sets, ranks=2)
            if parallel:
                print(describe("2 ranks", parallel))
            if parallel and fine:
                print(f"  speed-up {fine['run_wall_s'] / parallel['run_wall_s']:.2f} whole run, "
                      f"{fine['wall_time_s'] / parallel['wall_time_s']:.2f} solve (goal >= 1.5); "
                      f"2 ranks - 1: {differences(fine, parallel)} (goal within 0.1 %)")


if __name__ == "__main__":
    main()
