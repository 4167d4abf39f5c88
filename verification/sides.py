"""The sides a campaign case compares: a small registry of callables (SPEC 8).

A side turns (scene, overrides, options) into a SPEC 9 result directory:

* ``edem`` / ``dem``: the discrete solver (:func:`edem.solver.run`);
* ``fe-slab`` / ``fe-layer``: the dolfinx reference (``fem_reference.run_scene``), reported as
  "unavailable" (never faked) while that entry point or dolfinx is missing;
* ``closed-form:<name>``: a closed form of :mod:`verification.closed_forms`.

Bad input (InputError) and "no equilibrium" (SolverError) are the side's *refusal*: the outcome
says so with the message, which the stability campaign checks against its declared outcome.
"""

from __future__ import annotations

import importlib
import importlib.util
import time
import traceback
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from edem.errors import InputError, SolverError

OK, REFUSED, UNAVAILABLE, ERROR = "ok", "refused", "unavailable", "error"


@dataclass(frozen=True)
class SideOutcome:
    """What running one side produced."""

    side: str
    status: str  # ok | refused | unavailable | error
    result_dir: str | None  # the SPEC 9 result directory when status is ok
    message: str  # the refusal / unavailability / error message ("" when ok)
    wall_time_s: float
    error_type: str | None = None  # InputError, SolverError, ... when not ok

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


SideRunner = Callable[[str, dict[str, Any], Path, dict[str, Any]], str]


def _run_discrete(method: str) -> SideRunner:
    def runner(scene_ref: str, overrides: dict[str, Any], out_dir: Path, options: dict[str, Any]) -> str:
        from edem.results import write_results
        from edem.scene import load_scene
        from edem.solver import run

        scene = load_scene(scene_ref, overrides)
        write_results(run(scene, method), out_dir)
        return str(out_dir)

    runner.__doc__ = f"{method.upper()} (edem.solver.run) into a SPEC 9 result directory."
    return runner


def fe_availability() -> str | None:
    """None when the FE reference can run, else why not (dolfinx or fem_reference.run_scene missing)."""
    if importlib.util.find_spec("dolfinx") is None:
        return "FE reference not available: dolfinx is not installed (pip install -e '.[fe]')"
    try:
        module = importlib.import_module("fem_reference")
    except Exception as exc:  # the package is being written: any import failure means "not available"
        return f"FE reference not available: importing fem_reference failed ({type(exc).__name__}: {exc})"
    if not hasattr(module, "run_scene"):
        return "FE reference not available: fem_reference.run_scene does not exist yet"
    return None


class UnavailableError(Exception):
    """A side that cannot run on this installation (e.g. no FE reference yet)."""


def _run_fe(model: str) -> SideRunner:
    def runner(scene_ref: str, overrides: dict[str, Any], out_dir: Path, options: dict[str, Any]) -> str:
        why = fe_availability()
        if why is not None:
            raise UnavailableError(why)
        import fem_reference

        from edem.scene import load_scene

        scene = load_scene(scene_ref, overrides)
        kwargs = {k: options[k] for k in ("mesh_size_mm", "degree") if k in options}
        fem_reference.run_scene(scene, model=model, out_dir=out_dir, **kwargs)
        return str(out_dir)

    runner.__doc__ = f"The FE reference, {model} model (fem_reference.run_scene), SPEC 5."
    return runner


def _run_closed_form(scene_ref: str, overrides: dict[str, Any], out_dir: Path, options: dict[str, Any], name: str) -> str:
    from verification.closed_forms import solve_closed_form, write_closed_form_results

    start = time.perf_counter()
    scene, solution = solve_closed_form(name, scene_ref, overrides)
    write_closed_form_results(scene, solution, out_dir, wall_time_s=time.perf_counter() - start)
    return str(out_dir)


SIDES: dict[str, SideRunner] = {
    "edem": _run_discrete("edem"),
    "dem": _run_discrete("dem"),
    "fe-slab": _run_fe("slab"),
    "fe-layer": _run_fe("layer"),
}
CLOSED_FORM_PREFIX = "closed-form:"


def side_names() -> list[str]:
    """Every side a case may name (closed forms as closed-form:<name>)."""
    from verification.closed_forms import CLOSED_FORMS

    return list(SIDES) + [CLOSED_FORM_PREFIX + name for name in CLOSED_FORMS]


def is_fe_side(side: str) -> bool:
    return side.startswith("fe-")


def check_side(side: str) -> None:
    """InputError unless ``side`` names a registered side."""
    if side not in side_names():
        raise InputError(f"unknown side '{side}'", key="sides", expected="one of " + ", ".join(side_names()))


def run_side(side: str, scene_ref: str, overrides: dict[str, Any], out_dir: str | Path, options: dict[str, Any] | None = None) -> SideOutcome:
    """Run one side into ``out_dir``; refusals, unavailability and crashes become the outcome."""
    check_side(side)
    out = Path(out_dir)
    start = time.perf_counter()
    try:
        if side.startswith(CLOSED_FORM_PREFIX):
            _run_closed_form(scene_ref, overrides, out, options or {}, side[len(CLOSED_FORM_PREFIX) :])
        else:
            SIDES[side](scene_ref, overrides, out, options or {})
    except (InputError, SolverError) as exc:
        return SideOutcome(side, REFUSED, None, str(exc), time.perf_counter() - start, type(exc).__name__)
    except UnavailableError as exc:
        return SideOutcome(side, UNAVAILABLE, None, str(exc), time.perf_counter() - start, "UnavailableError")
    except Exception as exc:  # a bug: keep the traceback for the report, never crash the campaign
        text = "".join(traceback.format_exception_only(type(exc), exc)).strip()
        tail = traceback.format_exc().strip().splitlines()[-6:]
        return SideOutcome(side, ERROR, None, text + "\n" + "\n".join(tail), time.perf_counter() - start, type(exc).__name__)
    return SideOutcome(side, OK, str(out), "", time.perf_counter() - start)
