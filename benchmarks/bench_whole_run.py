"""The whole `edem run` against its solve: a 65-point EDEM stance from mesh files, independent
springs, at ~3k and ~13k springs (goal: whole run <= imports + 2 x solve).

For each size the ideal ankle is built (geometries.builders, ``mesh_size_mm``; the thesis's
geometry, without cartilage), written as binary STL files (as segmentation software writes
them), and the built-in ``ideal-stance`` scene is pointed at them (its load, kinematics,
constraints and ligaments, with the builder's attachment points; the thesis's threshold law on
independent springs). Then, median of ``--rounds``, three subprocesses a round:

* whole: ``python -m edem run scene.toml --out NEW_DIR`` as a user runs it, wall time (start-up,
  imports, scene loading, solve, result directory; a new directory each time, as a first run);
* imports: a subprocess that only imports every module that run had imported (recorded from
  the run's own ``sys.modules``, in import order), plus the interpreter's start-up;
* the same run with those modules imported first and its stages timed inside the process, so
  that no stage counts an import: scene (``edem.scene.load_scene``: reading, cleaning and
  orienting the meshes, the load), set-up (``setup_time_s``: the ray caster's scene, the bed,
  the pre-flight), solve (``wall_time_s``: the time points), writing (``write_results``: the
  pressure maps, their regularised peak, the manifest and its fsyncs) and other (the rest of
  whole - imports: start-up and exit, and in the command the provenance's git calls, the
  checks, the printing, the run outside its two timers);
* ratio: (whole - imports) / solve, with the solve of the whole run's own summary.json. Both
  subprocesses start an interpreter and import ~900 modules (0.5-0.8 s, varying by 0.1 s from
  one to the next on a shared machine), so the difference is noisy at 3k springs; the same
  ratio measured inside the staged run, its command's wall time over its solve, is printed
  beside it (no import in it, no start-up or exit);
* the same by the CPU time (user + system, threads included), which a loaded machine's waits for
  a core leave out: the whole run's and the import-only subprocess's, over the staged run's
  ``edem.solver.run`` (set-up and solve: the solve's own CPU time is not recorded), and the
  writing's.

Run from the repository root (``PYTHONPATH=$PWD``); ``PYTHONPATH=/path/to/other/tree`` measures
another version of the code (the mesh files are built by the imported tree's builders).
``--baseline /path/to/other/tree`` measures that tree too, in the same rounds (its three
subprocesses before this tree's, each round), and prints both and the change: a before/after
comparison in one run, under the same load.

``--builtin ideal-stance`` measures a built-in scene as it is the same way (there, the cartilage
EDEM stance: the gap law on both layers, the coupled layer, its geometry built by gmsh).

    PYTHONPATH=$PWD .venv/bin/python benchmarks/bench_whole_run.py [--rounds 5] [--sizes 0.94 0.45] [--builtin ideal-stance] [--baseline TREE]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

#: runs `edem run` and records the modules it imported (in import order) to the file named by
#: the environment variable, so that the import-only subprocess imports exactly the same ones
_RUN_AND_RECORD = """
import os, sys
from edem.cli import main
code = main(sys.argv[1:])
with open(os.environ["BENCH_MODULES_FILE"], "w") as f:
    f.write("\\n".join(name for name in list(sys.modules) if not name.startswith("__")))
sys.exit(code)
"""

_IMPORT_ONLY = """
import importlib, os
for name in open(os.environ["BENCH_MODULES_FILE"]).read().split():
    try:
        importlib.import_module(name)
    except Exception:
        pass
"""

#: the run with every module imported first and its stages timed (seconds, to BENCH_STAGES_FILE)
_RUN_STAGES = _IMPORT_ONLY + """
import json, sys, time
import edem.results, edem.scene, edem.solver
stages = {}

def timed(module, name):
    function = getattr(module, name)
    def wrapper(*args, **kwargs):
        start, cpu = time.perf_counter(), time.process_time()
        try:
            return function(*args, **kwargs)
        finally:
            stages[name] = stages.get(name, 0.0) + time.perf_counter() - start
            stages[name + " cpu"] = stages.get(name + " cpu", 0.0) + time.process_time() - cpu
    setattr(module, name, wrapper)  # (edem.cli imports them when the command runs)

timed(edem.scene, "load_scene")
timed(edem.solver, "run")
timed(edem.results, "write_results")
from edem.cli import main
start = time.perf_counter()
code = main(sys.argv[1:])
stages["main"] = time.perf_counter() - start
with open(os.environ["BENCH_STAGES_FILE"], "w") as f:
    json.dump(stages, f)
sys.exit(code)
"""


def write_scene(root: Path, mesh_size_mm: float) -> tuple[Path, str]:
    """ideal-stance on STL files of the ideal ankle at ``mesh_size_mm``: the scene path and its name."""
    import tomli_w

    from edem.scene import resolve_scene_path
    from geometries.builders import build_geometry
    from geometries.mesh_files import write_surface

    built = build_geometry("ideal_ankle", {"mesh_size_mm": mesh_size_mm, "cartilage": False})  # the thesis's cylinder under a plane
    write_surface(root / "talus.stl", built.mobile, binary=True)
    write_surface(root / "tibia.stl", built.fixed, binary=True)
    data = tomllib.loads(resolve_scene_path("ideal-stance").read_text(encoding="utf-8"))
    data["scene"]["name"] = f"stance-files-{built.mobile.n_triangles}"
    data["geometry"] = {"mobile": "talus.stl", "fixed": "tibia.stl"}
    # the thesis's law on independent springs (the scene's default is the gap law on both cartilage
    # layers, coupled: a file pair carries no bones to measure the layers to)
    data["cartilage"].update(law="threshold", coupling="none")
    if built.reference_point_mm is not None:
        data["geometry"]["reference_point_mm"] = [float(x) for x in built.reference_point_mm]
    points = {lig.name: lig for lig in built.ligaments}
    for ligament in data.get("ligaments", []):
        ligament["mobile_point_mm"] = [float(x) for x in points[ligament["name"]].mobile_point_mm]
        ligament["fixed_point_mm"] = [float(x) for x in points[ligament["name"]].fixed_point_mm]
    scene = root / "scene.toml"
    scene.write_text(tomli_w.dumps(data), encoding="utf-8")
    return scene, data["scene"]["name"]


def timed(args: list[str], env: dict[str, str], cwd: Path) -> tuple[float, float]:
    """Wall time and CPU time (user + system) of a subprocess, run outside any source tree
    (``python -c`` puts its working directory first on sys.path: PYTHONPATH alone picks the tree)."""
    start, before = time.perf_counter(), resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(args, env=env, cwd=cwd, check=True, stdout=subprocess.DEVNULL)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.perf_counter() - start, (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)


STAGES = ("scene", "set-up", "solve", "writing", "other")


def measure(run, case: Path, root: Path, env: dict[str, str], tag: str) -> dict[str, float]:
    """One round of the three subprocesses (whole, imports, staged) of one tree: its figures (s)."""
    figures: dict[str, float] = {}
    figures["whole"], figures["whole cpu"] = timed(run(_RUN_AND_RECORD, case / f"whole-{tag}"), env, root)
    figures["imports"], figures["imports cpu"] = timed([sys.executable, "-c", _IMPORT_ONLY], env, root)
    summary = json.loads((case / f"whole-{tag}" / "summary.json").read_text())
    figures["solve of the whole run"] = summary["wall_time_s"]
    timed(run(_RUN_STAGES, case / f"stages-{tag}"), env, root)
    stages = json.loads((root / "stages.json").read_text())
    staged = json.loads((case / f"stages-{tag}" / "summary.json").read_text())
    figures["scene"] = stages["load_scene"]
    figures["set-up"] = staged.get("setup_time_s", 0.0)
    figures["solve"] = staged["wall_time_s"]
    figures["writing"] = stages["write_results"]
    figures["other"] = figures["whole"] - figures["imports"] - sum(figures[s] for s in ("scene", "set-up", "solve", "writing"))
    figures["other in main"] = stages["main"] - stages["load_scene"] - stages["run"] - stages["write_results"]
    figures["ratio"] = (figures["whole"] - figures["imports"]) / figures["solve of the whole run"]
    figures["command"] = stages["main"]
    figures["ratio in process"] = stages["main"] / staged["wall_time_s"]
    # by the CPU time, which a loaded machine's waits for a core leave out: the run's (set-up and
    # solve) as the denominator, the solve's own CPU time not being recorded
    figures["run cpu"], figures["writing cpu"] = stages["run cpu"], stages["write_results cpu"]
    figures["cpu ratio"] = (figures["whole cpu"] - figures["imports cpu"]) / stages["run cpu"]
    figures["springs"], figures["points"] = summary["n_springs"], summary["steps"]
    return figures


def report(label: str, m: dict[str, float], rounds: int) -> None:
    beyond = m["whole"] - m["imports"]
    print(f"{label}: {m['springs']:.0f} springs x {m['points']:.0f} points, median of {rounds}: "
          f"whole {m['whole']:.3f} s, imports {m['imports']:.3f} s, solve {m['solve of the whole run']:.3f} s; "
          f"(whole - imports) / solve = {m['ratio']:.1f} (goal <= 2); the command with its modules imported first, "
          f"{m['command']:.3f} s, over its solve: {m['ratio in process']:.1f}")
    print("    whole - imports = " + ", ".join(f"{stage} {m[stage]:.3f} s ({100 * m[stage] / beyond:.0f} %)" for stage in STAGES)
          + f" (of which {m['other in main']:.3f} s in the command: the provenance's git calls, the checks, the printing)")
    print(f"    CPU time: whole {m['whole cpu']:.3f} s, imports {m['imports cpu']:.3f} s, the run (set-up and solve) {m['run cpu']:.3f} s, "
          f"writing {m['writing cpu']:.3f} s; (whole - imports) / run = {m['cpu ratio']:.1f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--sizes", type=float, nargs="*", default=[0.94, 0.45], help="mesh_size_mm of the ideal ankle (0.94: ~3k springs)")
    parser.add_argument("--builtin", nargs="*", default=[], metavar="SCENE",
                        help="also built-in scenes as they are (e.g. ideal-stance: the cartilage EDEM stance, coupled layer)")
    parser.add_argument("--baseline", metavar="TREE", help="another source tree measured in the same rounds (before/after)")
    args = parser.parse_args()
    import edem

    print(f"edem from {Path(edem.__file__).parent}; load {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores"
          + (f"; baseline {args.baseline}" if args.baseline else ""))
    with tempfile.TemporaryDirectory(prefix="bench_whole_run_") as tmp:
        root = Path(tmp)
        # one BLAS thread, as `edem run` sets before numpy loads (edem.cli.main): the import-only and
        # the staged runs load numpy before main, and OpenBLAS's threads spin on a busy machine
        env = {"OPENBLAS_NUM_THREADS": "1", **os.environ, "BENCH_MODULES_FILE": str(root / "modules.txt"),
               "BENCH_STAGES_FILE": str(root / "stages.json")}
        trees = {"this tree": env}
        if args.baseline:
            # the baseline first in each round: its own module list (modules.txt is rewritten by each whole run)
            trees = {"baseline": {**env, "PYTHONPATH": str(Path(args.baseline).resolve())}, **trees}
        for size in [*args.sizes, *args.builtin]:
            case = root / f"case-{size}"
            case.mkdir()
            if isinstance(size, float):
                scene, label = write_scene(case, size)
            else:
                scene, label = size, size

            def run(script: str, out: Path) -> list[str]:
                return [sys.executable, "-c", script, "run", str(scene), "--out", str(out)]

            for name, tree_env in trees.items():
                timed(run(_RUN_AND_RECORD, case / f"warm-up-{name.replace(' ', '-')}"), tree_env, root)  # file caches, compiled bytecode
            rounds: dict[str, dict[str, list[float]]] = {name: {} for name in trees}
            for k in range(args.rounds):
                for name, tree_env in trees.items():
                    for key, value in measure(run, case, root, tree_env, f"{name.replace(' ', '-')}-{k}").items():
                        rounds[name].setdefault(key, []).append(value)
            medians = {name: {key: statistics.median(values) for key, values in figures.items()} for name, figures in rounds.items()}
            for name, m in medians.items():
                report(label + (f" [{name}]" if args.baseline else ""), m, args.rounds)
            if args.baseline:
                before, after = medians["baseline"], medians["this tree"]
                print(f"    before -> after: (whole - imports) / solve {before['ratio']:.2f} -> {after['ratio']:.2f}; "
                      f"whole - imports {before['whole'] - before['imports']:.3f} -> {after['whole'] - after['imports']:.3f} s; "
                      + ", ".join(f"{stage} {before[stage]:.3f} -> {after[stage]:.3f} s" for stage in ("writing", "scene", "set-up", "solve"))
                      + f"; CPU: (whole - imports) / run {before['cpu ratio']:.2f} -> {after['cpu ratio']:.2f}, "
                      f"whole - imports {before['whole cpu'] - before['imports cpu']:.3f} -> {after['whole cpu'] - after['imports cpu']:.3f} s, "
                      f"writing {before['writing cpu']:.3f} -> {after['writing cpu']:.3f} s")


if __name__ == "__main__":
    main()
