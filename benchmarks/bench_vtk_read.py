"""Cost of reading user VTK files (.vtk, .vtp, .vtu) in a forked child process (docs/method.md#8-built-in-geometries).

VTK's C++ readers trust their input: damage not yet seen can crash the process. The VTK family
(:mod:`geometries.mesh_files.vtk_family`) therefore reads each file in a forked child, whose
crash becomes an InputError naming the file. This benchmark times, per file, the read of the
same files by the same VTK code in this process (before) and in the forked child (after), for
icosphere surfaces of about 1.3k, 20k and 330k triangles in each format (legacy .vtk and .vtu
written by meshio, .vtp by VTK), and the whole ``read_surface`` (with the child) for scale.

Prints the median of 7 timed rounds after one warm-up, and the ratio after / before.
Run: ``.venv/bin/python benchmarks/bench_vtk_read.py`` (about 30 s).
"""

from __future__ import annotations

import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from geometries.builders import icosphere  # noqa: E402
from geometries.mesh_files import read_surface, vtk_family, write_surface  # noqa: E402
from geometries.surface import TriangleSurface  # noqa: E402

ROUNDS = 7
SUBDIVISIONS = (3, 5, 7)  # 1280, 20480, 327680 triangles


def median_ms(function, *args) -> float:
    function(*args)  # warm-up: VTK's modules, the file in the page cache
    times = []
    for _ in range(ROUNDS):
        start = time.perf_counter()
        function(*args)
        times.append(time.perf_counter() - start)
    return 1e3 * statistics.median(times)


def in_process(path: Path) -> None:
    """The read as it was: the header checks and VTK's readers in this process."""
    vtk_family._check_header(path, None)
    vtk_family._read_with_vtk(path, None)


def main() -> None:
    vtk_family.load_vtk()
    print(f"{'file':<10} {'triangles':>9} {'in process ms':>14} {'forked child ms':>16} {'ratio':>6} {'read_surface ms':>16}")
    with tempfile.TemporaryDirectory() as tmp:
        for subdivisions in SUBDIVISIONS:
            vertices, triangles = icosphere(subdivisions, 20.0)
            surface = TriangleSurface(vertices, triangles)
            for suffix in (".vtk", ".vtu", ".vtp"):
                path = Path(tmp) / f"sphere{subdivisions}{suffix}"
                write_surface(path, surface)
                before = median_ms(in_process, path)
                after = median_ms(vtk_family.read, path, None)
                whole = median_ms(read_surface, path)
                print(f"{suffix:<10} {len(triangles):>9} {before:>14.2f} {after:>16.2f} {after / before:>6.2f} {whole:>16.2f}")


if __name__ == "__main__":
    main()
