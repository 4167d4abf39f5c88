"""Reading a load file of 1e6 rows (issue 13: "in seconds"): CSV and OpenSim .sto, median of 3.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_loads.py [--rows 1000000]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from edem.loads import load_series_from_table  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=1_000_000)
    args = parser.parse_args()
    n = args.rows
    t = np.arange(n) * 1e-3
    force = np.column_stack([np.sin(t), np.cos(t), 500.0 + 100.0 * np.sin(3 * t)])
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        csv_path, sto_path = root / "load.csv", root / "load.sto"
        np.savetxt(csv_path, np.column_stack([t, force]), delimiter=",", fmt="%.6f",
                   header="time_s,force_x_n,force_y_n,force_z_n", comments="")
        np.savetxt(sto_path, np.column_stack([t, force]), delimiter="\t", fmt="%.6f",
                   header="version=1\ninDegrees=no\nendheader\ntime\tj_fx\tj_fy\tj_fz", comments="")
        for path in (csv_path, sto_path):
            times = []
            for _ in range(3):
                start = time.perf_counter()
                series = load_series_from_table({"file": path.name}, root / "scene.toml")
                times.append(time.perf_counter() - start)
            assert series.time_s.size == n and np.allclose(series.force_n[:, 2], force[:, 2], atol=1e-6)
            print(f"{path.suffix:5s} {n:9,d} rows: {statistics.median(times):.2f} s (median of 3)")


if __name__ == "__main__":
    main()
