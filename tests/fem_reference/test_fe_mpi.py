"""The FE contact solves give the same numbers on 1 and 2 MPI ranks (no serial-only
assumptions: sums by allreduce, nodal data gathered, extra unknowns owned by rank 0)."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("dolfinx_solver")

pytestmark = pytest.mark.fe

HERE = Path(__file__).resolve().parent


def _run(n: int) -> dict:
    exe = Path(sys.executable).with_name("mpiexec")
    mpiexec = str(exe) if exe.exists() else shutil.which("mpiexec")
    if mpiexec is None:
        pytest.skip("mpiexec not found")
    out = subprocess.run([mpiexec, "-n", str(n), sys.executable, str(HERE / "mpi_case.py")],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-4000:]
    line = [ln for ln in out.stdout.splitlines() if ln.startswith("RESULT ")]
    assert len(line) == 1, out.stdout
    return json.loads(line[0][len("RESULT "):])


def test_two_ranks_match_one_rank():
    """Invariant: displacement, peak pressure, area, gathered node count and DOF count are the
    same on 1 and 2 ranks; force balance holds on both."""
    one, two = _run(1), _run(2)
    print(f"\n[fe] MPI 1 rank: {one}\n[fe] MPI 2 ranks: {two}")
    for key in one:
        d1, p1, a1, res1, n1, dofs1 = one[key]
        d2, p2, a2, res2, n2, dofs2 = two[key]
        assert d2 == pytest.approx(d1, rel=1e-8), key
        assert p2 == pytest.approx(p1, rel=1e-8), key
        assert a2 == pytest.approx(a1, rel=1e-8), key
        assert n1 == n2 and dofs1 == dofs2, key
        assert res1 < 1e-6 and res2 < 1e-6, key
