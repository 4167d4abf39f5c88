"""The whole `edem run` against its solve: a 65-point EDEM stance from mesh files, independent
springs, at ~3k and ~13k springs (goal: whole run <= imports + 2 x solve).

For each size the ideal ankle is built (geometries.builders, ``mesh_size_mm``), written as
binary STL files (as segmentation software writes them), and the built-in ``ideal-stance`` scene is pointed at them (its load, kinematics,
constraints and ligaments, with the builder's attachment points). Then, median of ``--rounds``:

* whole: ``python -m edem run scene.toml --out NEW_DIR`` as a subprocess, wall time (start-up,
  imports, scene loading, solve, result directory; a new directory each time, as a first run);
* imports: a subprocess that only imports every module that run had imported (recorded from
  the run's own ``sys.modules``, in import order), plus the interpreter's start-up;
* solve: ``wall_time_s`` of the run's summary.json (and ``setup_time_s`` where the summary has it);
* ratio: (whole - imports) / solve.

Run from the repository root (``PYTHONPATH=$PWD``); ``PYTHONPATH=/path/to/other/tree`` measures
another version of the code (the mesh files are built by the imported tree's builders).

    PYTHONPATH=$PWD .venv/bin/python benchmarks/bench_whole_run.py [--rounds 3] [--sizes 0.94 0.45]
"""

from __future__ import annotations

import argparse
import json
import os
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


def write_scene(root: Path, mesh_size_mm: float) -> tuple[Path, int]:
    """ideal-stance on STL files of the ideal ankle at ``mesh_size_mm``: the scene path and its triangle count."""
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
    return scene, built.mobile.n_triangles


def timed(args: list[str], env: dict[str, str], cwd: Path) -> float:
    """Wall time of a subprocess, run outside any source tree (``python -c`` puts its working
    directory first on sys.path: PYTHONPATH alone picks the tree)."""
    start = time.perf_counter()
    subprocess.run(args, env=env, cwd=cwd, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--sizes", type=float, nargs="+", default=[0.94, 0.45], help="mesh_size_mm of the ideal ankle (0.94: ~3k springs)")
    args = parser.parse_args()
    import edem

    print(f"edem from {Path(edem.__file__).parent}")
    with tempfile.TemporaryDirectory(prefix="bench_whole_run_") as tmp:
        root = Path(tmp)
        env = {**os.environ, "BENCH_MODULES_FILE": str(root / "modules.txt")}
        for size in args.sizes:
            case = root / f"h{size}"
            case.mkdir()
            scene, n_triangles = write_scene(case, size)
            def run(out: Path) -> list[str]:
                return [sys.executable, "-c", _RUN_AND_RECORD, "run", str(scene), "--out", str(out)]

            timed(run(case / "warm-up"), env, root)  # file caches, compiled bytecode
            whole, imports, solve, setup = [], [], [], []
            for k in range(args.rounds):
                out = case / f"result-{k}"
                whole.append(timed(run(out), env, root))
                summary = json.loads((out / "summary.json").read_text())
                solve.append(summary["wall_time_s"])
                setup.append(summary.get("setup_time_s"))
                imports.append(timed([sys.executable, "-c", _IMPORT_ONLY], env, root))
            w, i, s = statistics.median(whole), statistics.median(imports), statistics.median(solve)
            setup_text = "" if setup[0] is None else f", set-up {statistics.median(setup):.3f} s"
            print(f"{summary['n_springs']:6d} springs ({n_triangles} triangles) x {summary['steps']} points: whole {w:.2f} s, "
                  f"imports {i:.2f} s, solve {s:.3f} s{setup_text}; (whole - imports) / solve = {(w - i) / s:.1f} "
                  f"(goal <= 2; median of {args.rounds})")


if __name__ == "__main__":
    main()
