"""Progress lines from inside one FE solve (fem_reference.progress, `edem fe --progress`), and the
VI cross-check's refusal when its inner solve does not converge."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

pytest.importorskip("dolfinx_solver")

from fe_cases import MATERIAL  # noqa: E402

from edem.cli import main  # noqa: E402
from fem_reference import FEContactProblem, RigidPlane, SolverOptions, solve_contact, solve_contact_vi  # noqa: E402
from fem_reference import meshes  # noqa: E402
from fem_reference.problem import FEConvergenceError  # noqa: E402
from fem_reference.progress import SolveProgress  # noqa: E402

pytestmark = pytest.mark.fe

ROOT = Path(__file__).resolve().parents[2]
PLATES = str(ROOT / "verification" / "scenes" / "flat-plates.toml")
NEWTON = re.compile(r"Newton (\d+): \|F\| = (\S+) N, (\d+) contact nodes")
KRYLOV = re.compile(r"inner (\S+): iteration (\d+), \|r\| = (\S+)")


def _slab_problem(comm, **solver):
    """A free-sided slab pressed on a plane: contact spreads over the top face during Newton."""
    msh = meshes.box_slab(comm, 4.0, 4.0, 1.0, (4, 4, 3), confined=False)
    return FEContactProblem(mesh=msh, obstacle=RigidPlane((0, 0, 1.0), (0, 0, -1.0)), force_n=(0, 0, 20.0),
                            element="P1", solver=SolverOptions(**solver), **MATERIAL)


def test_forced_progress_writes_each_newton_iteration_and_the_krylov_iterations(comm):
    """Invariant: one Newton line per iteration, numbered 0, 1, ... up to the iterations the
    result reports, the last residual the smallest (converged), contact nodes at the end; on
    the Krylov path the inner iterations of each solve count up from 0."""
    lines: list[str] = []
    progress = SolveProgress(lines.append, label="test", quiet_s=0.0, krylov_every_s=0.0)
    result = solve_contact(_slab_problem(comm, linear_solver="iterative"), comm, progress=progress)
    assert result.linear_solver == "iterative"
    newton = [NEWTON.search(line) for line in lines if NEWTON.search(line)]
    numbers = [int(m.group(1)) for m in newton]
    assert numbers == list(range(result.newton_iterations + 1))
    residuals = [float(m.group(2)) for m in newton]
    assert residuals[-1] == min(residuals)
    assert int(newton[-1].group(3)) > 0
    assert all(line.startswith("fe: test: ") for line in lines)
    krylov = [int(m.group(2)) for m in map(KRYLOV.search, lines) if m]
    assert krylov and krylov[0] == 0
    # within one inner solve the iterations go up by one; a new solve starts again at 0
    assert all(b == a + 1 or b == 0 for a, b in zip(krylov, krylov[1:]))
    assert krylov.count(0) >= result.newton_iterations  # at least one inner solve per Newton step


def test_quiet_progress_writes_nothing_for_a_short_solve(comm):
    """A solve shorter than quiet_s (a terminal's default) leaves the screen alone."""
    lines: list[str] = []
    solve_contact(_slab_problem(comm), comm, progress=SolveProgress(lines.append, quiet_s=3600.0))
    assert lines == []


def test_edem_fe_progress_flag(tmp_path, capsys):
    """`edem fe --progress` writes the Newton lines of each time point on stderr, monotone per
    solve; --no-progress (and the default off a terminal) writes none."""
    args = ["fe", PLATES, "--degree", "1", "--mesh-size", "2.0"]
    assert main([*args, "--out", str(tmp_path / "on"), "--progress"]) == 0
    err = capsys.readouterr().err
    numbers = [int(m.group(1)) for m in NEWTON.finditer(err)]
    assert numbers and numbers[0] == 0
    assert all(b == a + 1 or b == 0 for a, b in zip(numbers, numbers[1:]))
    assert "time point 0" in err
    assert main([*args, "--out", str(tmp_path / "off"), "--no-progress"]) == 0
    assert "Newton" not in capsys.readouterr().err


def test_vi_inner_solve_that_does_not_converge_is_refused_with_its_residual(comm):
    """The VI cross-check's inner vinewtonrsls limited to one iteration cannot reach its
    tolerance: FEConvergenceError naming the translation, the reason and the last residual."""
    msh = meshes.box_slab(comm, 4.0, 4.0, 1.0, (2, 2, 2), confined=False)
    problem = FEContactProblem(mesh=msh, obstacle=RigidPlane((0, 0, 1.0), (0, 0, -1.0)), force_n=(0, 0, 20.0),
                               element="P1", solver=SolverOptions(petsc_options=(("snes_max_it", "1"),)), **MATERIAL)
    with pytest.raises(FEConvergenceError, match="VI contact solve did not converge at translation") as err:
        solve_contact_vi(problem, comm)
    assert err.value.iterations == 1
    assert math.isfinite(err.value.residual_norm) and err.value.residual_norm > 0


def test_krylov_lines_are_throttled_and_wait_for_quiet_s():
    """With a fake clock: nothing before quiet_s, then at most one Krylov line per
    krylov_every_s, labelled with the Newton step being solved (the one after the last line)."""
    now = [0.0]
    lines: list[str] = []
    progress = SolveProgress(lines.append, label="t", quiet_s=1.0, krylov_every_s=2.0, clock=lambda: now[0])
    for step in range(50):  # an inner solve of 50 iterations, 0.1 s each
        now[0] = 0.1 * step
        progress.krylov(step, 1.0 / (step + 1), "cg+gamg")
    iterations = [int(m.group(2)) for m in map(KRYLOV.search, lines) if m]
    assert iterations == [10, 30]  # at 1.0 s (quiet_s) and 3.0 s, not at 2.0 s (within 2 s of the last)
    progress.newton(3, 0.5, 10, 1, 0)
    assert lines[-1].startswith("fe: t: Newton 3: |F| = 5.000e-01 N, 10 contact nodes (+1 -0)")
    now[0] = 10.0
    progress.krylov(0, 1.0, "cg+gamg")
    assert "Newton 4, inner cg+gamg: iteration 0" in lines[-1]
