"""A fine mobile mesh end to end: a 2M-triangle paraboloid (a 100 MB binary STL, like a fine MRI
surface) under a plane, `edem run` (DEM, independent springs) with one time point and with five,
each a subprocess: its wall time, peak resident memory and exit status (goal: the results written
in at most 4 GB, or the mesh refused up front with exit 2).

The paraboloid z = -(x^2 + y^2) / 120 mm over 40 x 40 mm, ``--cells`` x ``--cells`` squares of two
triangles (1000: 2M triangles, 0.04 mm edges), its top 0.2 mm under a plane; threshold law,
h_max 3.5 mm, 2000 N (five points: 500 to 2500 N), only tz free.

    PYTHONPATH=$PWD .venv/bin/python benchmarks/bench_fine_mesh.py [--cells 1000]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def write_scenes(root: Path, cells: int) -> list[Path]:
    from geometries.mesh_files import write_surface
    from geometries.surface import TriangleSurface

    x = np.linspace(-20.0, 20.0, cells + 1)
    xx, yy = np.meshgrid(x, x, indexing="ij")
    points = np.column_stack([xx.ravel(), yy.ravel(), -(xx.ravel() ** 2 + yy.ravel() ** 2) / 120.0])
    index = np.arange((cells + 1) ** 2).reshape(cells + 1, cells + 1)
    a, b, c, d = index[:-1, :-1].ravel(), index[1:, :-1].ravel(), index[1:, 1:].ravel(), index[:-1, 1:].ravel()
    triangles = np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])  # facing +z, the plane
    write_surface(root / "paraboloid.stl", TriangleSurface(points, triangles), binary=True)
    corners = np.array([[-30.0, -30.0, 0.2], [30.0, -30.0, 0.2], [30.0, 30.0, 0.2], [-30.0, 30.0, 0.2]])
    write_surface(root / "plane.stl", TriangleSurface(corners, np.array([[0, 2, 1], [0, 3, 2]])), binary=True)
    scenes = []
    for name, load in (("one", "force_n = [0.0, 0.0, 2000.0]"),
                       ("five", "time_s = [0.0, 0.1, 0.2, 0.3, 0.4]\nforce_n = [" + ", ".join(f"[0.0, 0.0, {f:.1f}]" for f in (500, 1000, 1500, 2000, 2500)) + "]")):
        path = root / f"{name}.toml"
        path.write_text(f'[scene]\nname = "paraboloid-{name}"\n[geometry]\nmobile = "paraboloid.stl"\nfixed = "plane.stl"\n'
                        '[cartilage]\nyoungs_modulus_mpa = 10.35\npoissons_ratio = 0.42\nlaw = "threshold"\nmax_spring_length_mm = 3.5\n'
                        f'[load]\n{load}\n[constraints]\nfixed_dofs = ["tx", "ty", "rx", "ry", "rz"]\n[solver]\nmethod = "dem"\n')
        scenes.append(path)
    return scenes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, default=1000, help="squares a side (1000: 2M triangles)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench_fine_mesh_") as tmp:
        root = Path(tmp)
        scenes = write_scenes(root, args.cells)
        print(f"{2 * args.cells**2:,} triangles, {(root / 'paraboloid.stl').stat().st_size / 1e6:.0f} MB STL")
        for scene in scenes:
            out = root / f"{scene.stem}-result"
            start = time.perf_counter()
            with open(root / f"{scene.stem}.err", "w+") as errors:
                # wait4: this child's own peak resident memory (ru_maxrss, kB on Linux)
                child = subprocess.Popen([sys.executable, "-m", "edem", "run", str(scene), "--out", str(out)], cwd=root,
                                         stdout=subprocess.DEVNULL, stderr=errors)
                _, status, usage = os.wait4(child.pid, 0)
                wall = time.perf_counter() - start
                child.returncode = code = os.waitstatus_to_exitcode(status)
                errors.seek(0)
                err = errors.read()
            line = f"{scene.stem:4s} time point(s): exit {code}, whole run {wall:.1f} s, peak resident {usage.ru_maxrss / 1e6:.2f} GB (goal <= 4)"
            if code == 0:
                summary = json.loads((out / "summary.json").read_text())
                setup = f", set-up {summary['setup_time_s']:.1f} s" if "setup_time_s" in summary else ""
                line += (f"; solve {summary['wall_time_s']:.1f} s{setup}, "
                         f"regularised peak {summary['regularised_peak_pressure_mpa']:.4g} MPa (raw {summary['peak_pressure_mpa']:.4g})")
            else:
                line += f": {err.strip().splitlines()[-1] if err.strip() else ''}"
            print(line)


if __name__ == "__main__":
    main()
