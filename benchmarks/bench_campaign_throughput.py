"""Campaign throughput on a quiet machine, projected from CPU times (issue 23 item 4: the
sensitivity grid in <= 60 s and the 1000-subject coupled population in <= 5 min, on 2 cores).

On a shared machine the wall time of a campaign measures the other users' load as much as the
campaign, so this measures CPU time (user + sys), which the load hardly changes, and projects:

    quiet wall = parent start-up + worker start-up + cases x mean CPU per case / jobs + report

* parent start-up: a fresh process importing the runner and the report, building the campaign
  and every case's cache key (what ``edem verify`` does before the first case starts);
* worker start-up: a fresh process importing what a worker imports, plus the first case's CPU
  beyond the mean (its lazy imports: gmsh, Embree, SciPy's sparse solvers);
* per case: ``--cases`` cases spread evenly over the campaign, run one after the other in this
  process through the runner's own ``execute_case`` (writes included), each timed;
* report: the HTML report of a finished run of the whole campaign (``--summary`` its
  metrics.json), drawn again here; without one it is not counted (say so).

    .venv/bin/python benchmarks/bench_campaign_throughput.py sensitivity population-coupled
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the command line runs (edem.cli.main), before numpy loads

import argparse
import json
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: the issue's goals, quiet wall time on 2 cores (s)
GOALS_S = {"sensitivity": 60.0, "population-coupled": 300.0}

PARENT = """
from verification.campaigns import get_campaign
from verification.runner import case_key, software_versions
from reports.html import write_campaign_report
campaign = get_campaign({name!r})
keys = [case_key(case) for case in campaign.cases]
software_versions()
"""
WORKER = "import verification.runner, verification.sides"


def child_cpu_s(code: str) -> float:
    """user + sys CPU seconds of a fresh Python process running ``code`` from the project root."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT, env=env)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def case_cpu_s(name: str, n_cases: int, work: Path) -> tuple[float, list[float]]:
    """CPU seconds of the first case (warm-up) and of each of ``n_cases`` further cases, spread
    evenly over the campaign, run in this process by the runner's execute_case."""
    from verification.campaigns import get_campaign
    from verification.runner import execute_case

    cases = list(get_campaign(name).cases)
    picked = cases[:: max(1, len(cases) // (n_cases + 1))][: n_cases + 1]
    times = []
    for case in picked:
        start = time.process_time()
        execute_case(case, str(work / "cases" / case.name), "bench")
        times.append(time.process_time() - start)
    return times[0], times[1:]


def report_cpu_s(summary_file: Path, work: Path) -> float:
    """CPU seconds to draw the report of a finished campaign again (its figures and tables)."""
    from reports.html import write_campaign_report

    summary = json.loads(summary_file.read_text(encoding="utf-8"))
    out = work / "report"  # a new directory: every figure is drawn (a finished run's are reused)
    out.mkdir()
    start = time.process_time()
    write_campaign_report(summary, out)
    return time.process_time() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("campaigns", nargs="+")
    parser.add_argument("--cases", type=int, default=30, help="cases timed per campaign (default 30)")
    parser.add_argument("--jobs", type=int, default=2, help="worker processes of the projection (default 2)")
    parser.add_argument("--summary", action="append", default=[], metavar="METRICS_JSON",
                        help="a finished run's metrics.json (one per campaign, in order) whose report is timed")
    args = parser.parse_args()
    load = os.getloadavg()
    print(f"load average {load[0]:.1f} {load[1]:.1f} {load[2]:.1f} (CPU times; wall times here would measure the load)")
    for index, name in enumerate(args.campaigns):
        from verification.campaigns import get_campaign

        n_total = len(get_campaign(name).cases)
        parent = child_cpu_s(PARENT.format(name=name))
        worker_import = child_cpu_s(WORKER)
        with tempfile.TemporaryDirectory(prefix="bench-throughput-") as tmp:
            first, per_case = case_cpu_s(name, args.cases, Path(tmp))
            mean, median = statistics.fmean(per_case), statistics.median(per_case)
            report = report_cpu_s(Path(args.summary[index]), Path(tmp)) if index < len(args.summary) else None
        worker = worker_import + max(first - mean, 0.0)
        cases = n_total * mean / args.jobs
        projected = parent + worker + cases + (report or 0.0)
        goal = GOALS_S.get(name)
        print(f"{name}: {n_total} cases; CPU per case mean {1e3 * mean:.0f} ms, median {1e3 * median:.0f} ms "
              f"(min {1e3 * min(per_case):.0f}, max {1e3 * max(per_case):.0f}; {len(per_case)} cases)")
        print(f"  start-up CPU: parent {parent:.2f} s, worker {worker:.2f} s (imports {worker_import:.2f} s + first case's extra "
              f"{max(first - mean, 0.0):.2f} s); report {'%.2f s' % report if report is not None else 'not timed (no --summary)'}")
        verdict = "" if goal is None else f"; goal <= {goal:.0f} s: {'met' if projected <= goal else 'MISSED'} ({projected / goal:.2f}x the goal)"
        print(f"  projected quiet wall with {args.jobs} jobs: {parent:.1f} + {worker:.1f} + {n_total} x {mean:.3f} / {args.jobs} "
              f"{'+ %.1f ' % report if report is not None else ''}= {projected:.1f} s{verdict}")


if __name__ == "__main__":
    main()
