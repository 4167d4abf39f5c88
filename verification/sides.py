"""The sides a campaign case compares: a small registry of callables (docs/method.md#7-comparison-metrics).

A side turns (scene, overrides, options) into a result directory (docs/result-format.md):

* ``edem`` / ``dem``: the discrete solver (:func:`edem.solver.run`);
* ``fe-<model>``: the dolfinx reference (``fem_reference.run_scene``) with one model of
  :data:`fem_reference.models.FE_MODELS` (``fe-slab``, ``fe-layer``; a model added there is a side
  here), reported as "unavailable" (never faked) while that entry point or dolfinx is missing (the
  registry itself imports without dolfinx);
* ``closed-form:<name>``: a closed form of :mod:`verification.closed_forms` (of the case's
  scene), or of an FE problem of :mod:`verification.fe_analytic` (``closed-form:hertz-line``,
  ``closed-form:confined-compression``: no scene, the case's options give the mesh);
* ``fe-problem:<name>``: the FE core (:func:`fem_reference.solve_contact`) on those closed-form
  problems, "unavailable" without dolfinx.

Options of a case reach its sides: ``mesh_size_mm``, ``degree``, ``element``,
``layers_through_thickness`` (:data:`FE_SCENE_OPTIONS`) and ``steps`` (the time points to solve)
for the FE reference of a scene; ``mesh_size_mm`` and ``element`` for an FE problem;
``frames`` for EDEM/DEM ("all", the default; "peak": only the pressure map of the time point
of peak pressure; "none": no pressure map, fixed body or .sto file, the optional files of
docs/result-format.md, for campaigns of hundreds of runs that need the time series only).

A side receives only the overrides and options it reads (:func:`side_inputs`): the FE sides never
see the override keys only the discrete bed reads (:data:`DEM_ONLY_OVERRIDES`, e.g.
``cartilage.coupling``), so two cases that differ only there run the identical FE, which the
runner computes once (:func:`is_shared_side`, verification.runner's side store).

Overrides are dotted scene keys (``--set``), plus ``<array>[*].<key>`` / ``<array>[<i>].<key>``
for arrays of tables (e.g. ``ligaments[*].youngs_modulus_mpa``), which
:func:`expand_array_overrides` turns into a whole-array override before the scene is loaded.

Bad input (InputError) and "no equilibrium" (SolverError) are the side's *refusal*: the outcome
says so with the message, which the stability campaign checks against its declared outcome.
"""

from __future__ import annotations

import copy
import importlib
import importlib.util
import inspect
import re
import time
import traceback
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from edem.atomic_dirs import ResultWriteError
from edem.beds import bed_keys
from geometries.errors import InputError, SolverError
from edem.resultdir import Provenance, provenance
from edem.results import write_results
from edem.scene import apply_overrides, load_scene, read_scene_toml, resolve_scene_path
from edem.solver import run
from fem_reference.models import FE_MODELS
from verification.closed_forms import CLOSED_FORMS, solve_closed_form, write_closed_form_results
from verification.fe_analytic import FE_PROBLEMS, run_fe_problem, write_exact_result
from verification.status import ERROR, OK, REFUSED, UNAVAILABLE


# The modules whose source a side's results depend on, with all they import (verification.sources):
# a campaign case's cache key hashes them, so editing anything else keeps its results.
DISCRETE_MODULES = ("edem.scene", "edem.solver", "edem.results")
FE_MODULES = ("edem.scene", "fem_reference.scene_run", "fem_reference.contact")
FE_PROBLEM_MODULES = ("verification.fe_analytic", "fem_reference")
CLOSED_FORM_MODULES = ("edem.scene", "verification.closed_forms")
FE_EXACT_MODULES = ("verification.fe_analytic",)
#: for a side runner that does not say (a stand-in): every package that can compute results
ANY_MODULES = ("geometries", "edem", "fem_reference", "verification")
#: scene keys only the discrete bed reads: the FE continuum has no such option (the thin-layer
#: coupling approximates the lateral coupling the continuum has anyway). The FE sides are run
#: without them (side_inputs), so their results cannot depend on them.
DEM_ONLY_OVERRIDES = tuple(f"cartilage.{key}" for key in bed_keys()) + (
    # how the discrete Kelvin-Voigt springs step (edem.viscoelastic); the FE twin steps by [fe] time_scheme
    "viscoelastic.contact_set", "viscoelastic.integrator", "viscoelastic.allow_unstable",
    # the springs' resolution (M resampled, its geometry unchanged): the FE meshes the scene's own M
    "geometry.spring_spacing_mm")
#: options of a case that reach the FE reference of its scene as fem_reference.run_scene's
#: settings (fem_reference.settings.resolve_settings: they override the scene's [fe] table)
FE_SCENE_OPTIONS = ("mesh_size_mm", "degree", "element", "layers_through_thickness", "contact_mesh_size_mm")
#: the options of a case the FE reference of a scene reads: its settings and the time points to solve
FE_OPTIONS = FE_SCENE_OPTIONS + ("steps",)


@dataclass(frozen=True)
class SideOutcome:
    """What running one side produced."""

    side: str
    status: str  # ok | refused | unavailable | error
    result_dir: str | None  # the result directory (docs/result-format.md) when status is ok
    message: str  # the refusal / unavailability / error message ("" when ok)
    wall_time_s: float
    error_type: str | None = None  # InputError, SolverError, ... when not ok

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


SideRunner = Callable[[str, dict[str, Any], Path, dict[str, Any]], str]


ARRAY_OVERRIDE = re.compile(r"^(?P<array>[A-Za-z_][A-Za-z0-9_]*)\[(?P<index>\*|\d+)\]\.(?P<key>[A-Za-z_][A-Za-z0-9_]*)$")


def expand_array_overrides(scene_ref: str, overrides: dict[str, Any]) -> dict[str, Any]:
    """Overrides with ``array[*].key`` / ``array[i].key`` replaced by the whole edited array.

    edem.scene.apply_overrides sets dotted keys of tables only; an array of tables (the scene's
    ``[[ligaments]]``) is read from the scene file, its entries edited, and set as one top-level
    key. Other overrides pass unchanged. InputError names the key when the array or index is missing.
    """
    if not any(ARRAY_OVERRIDE.match(k) for k in overrides):
        return dict(overrides)

    path = resolve_scene_path(scene_ref)
    data = read_scene_toml(path)
    plain = {k: v for k, v in overrides.items() if not ARRAY_OVERRIDE.match(k)}
    apply_overrides(data, dict(plain))
    arrays: dict[str, list[dict[str, Any]]] = {}
    for dotted, value in overrides.items():
        match = ARRAY_OVERRIDE.match(dotted)
        if match is None:
            continue
        name = match["array"]
        if name not in arrays:
            entries = data.get(name)
            if not isinstance(entries, list) or not entries or not all(isinstance(e, dict) for e in entries):
                raise InputError(f"the scene has no [[{name}]] entries", file=path, key=dotted, expected=f"a scene with [[{name}]] tables")
            arrays[name] = copy.deepcopy(entries)
        entries = arrays[name]
        if match["index"] == "*":
            targets = entries
        else:
            index = int(match["index"])
            if index >= len(entries):
                raise InputError(f"index {index} past the {len(entries)} [[{name}]] entries", file=path, key=dotted, expected=f"0 .. {len(entries) - 1} or *")
            targets = [entries[index]]
        for entry in targets:
            entry[match["key"]] = value
    return {**plain, **arrays}


FRAMES = ("all", "peak", "none")


def _write_discrete(result: Any, out_dir: Path, frames: str, record: Provenance) -> None:
    """write_results, or the same summary and time series with one pressure map (frames "peak")
    or none (frames "none"). Not flushed to disk (durable=False): a case's result directory is a
    cache the runner verifies against its manifest before use and re-runs when it does not."""
    if frames == "all":
        write_results(result, out_dir, provenance=record, durable=False)
        return
    if frames == "none":
        write_results(result, out_dir, note="no pressure maps (time series only)", provenance=record, durable=False,
                      time_series_only=True)
        return
    peak = max(range(len(result.steps)), key=lambda k: result.steps[k].peak_pressure_mpa)
    note = f"pressure map of the peak-pressure time point only (step {result.steps[peak].step})"
    write_results(result, out_dir, frame_steps=[peak], note=note, provenance=record, durable=False)


def _run_discrete(method: str) -> SideRunner:
    def runner(scene_ref: str, overrides: dict[str, Any], out_dir: Path, options: dict[str, Any]) -> str:
        frames = str(options.get("frames", "all"))
        if frames not in FRAMES:
            raise InputError(f"frames = {frames!r}", key="options.frames", expected=" or ".join(f'"{f}"' for f in FRAMES))
        scene = load_scene(scene_ref, overrides)
        # the provenance goes into the same atomic write: a full disk cannot leave a sealed result half annotated
        _write_discrete(run(scene, method), out_dir, frames, provenance(scene_ref, overrides, method=method))
        return str(out_dir)

    runner.__doc__ = f"{method.upper()} (edem.solver.run) into a result directory (docs/result-format.md)."
    runner.modules = DISCRETE_MODULES
    runner.reads_options = ("frames",)
    return runner


def fe_availability(entry_point: str = "run_scene") -> str | None:
    """None when the FE reference can run, else why not (dolfinx or fem_reference.<entry_point> missing)."""
    if importlib.util.find_spec("dolfinx") is None:
        return "FE reference not available: dolfinx is not installed (pip install -e '.[fe]')"
    try:
        module = importlib.import_module("fem_reference")
    except Exception as exc:  # a broken installation: any import failure means "not available"
        return f"FE reference not available: importing fem_reference failed ({type(exc).__name__}: {exc})"
    if not hasattr(module, entry_point):
        return f"FE reference not available: fem_reference.{entry_point} does not exist"
    return None


class UnavailableError(Exception):
    """A side that cannot run on this installation (e.g. no FE reference yet)."""


def _run_fe(model: str) -> SideRunner:
    def runner(scene_ref: str, overrides: dict[str, Any], out_dir: Path, options: dict[str, Any]) -> str:
        why = fe_availability()
        if why is not None:
            raise UnavailableError(why)
        import fem_reference

        scene = load_scene(scene_ref, overrides)
        kwargs = {k: options[k] for k in FE_OPTIONS if k in options}
        if "steps" in kwargs:
            try:
                params = inspect.signature(fem_reference.run_scene).parameters
            except (TypeError, ValueError):
                params = {}
            if params and "steps" not in params and not any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()):
                raise UnavailableError("FE reference not available: fem_reference.run_scene takes no steps= selection")
            kwargs["steps"] = list(kwargs["steps"])
        record = provenance(scene_ref, overrides, {"model": model, **{k: options[k] for k in FE_SCENE_OPTIONS if k in options}})
        fem_reference.run_scene(scene, model=model, out_dir=out_dir, provenance=record, **kwargs)
        return str(out_dir)

    runner.__doc__ = f"The FE reference, {model} model (fem_reference.run_scene), docs/method.md#6-the-fe-reference-and-its-discrete-twins."
    runner.modules = FE_MODULES
    runner.reads_options = FE_OPTIONS
    runner.ignores_overrides = DEM_ONLY_OVERRIDES
    runner.shared = True
    return runner


def _run_fe_problem(name: str) -> SideRunner:
    def runner(scene_ref: str, overrides: dict[str, Any], out_dir: Path, options: dict[str, Any]) -> str:
        why = fe_availability("solve_contact")
        if why is not None:
            raise UnavailableError(why)

        run_fe_problem(name, out_dir, options)
        return str(out_dir)

    runner.__doc__ = f"The FE core on the closed-form problem {name} (verification.fe_analytic), docs/method.md#6-the-fe-reference-and-its-discrete-twins."
    runner.modules = FE_PROBLEM_MODULES
    return runner


def _run_closed_form(scene_ref: str, overrides: dict[str, Any], out_dir: Path, options: dict[str, Any], name: str) -> str:
    if name in FE_PROBLEMS:
        write_exact_result(name, out_dir, options)
        return str(out_dir)
    start = time.perf_counter()
    scene, solution = solve_closed_form(name, scene_ref, overrides)
    write_closed_form_results(scene, solution, out_dir, wall_time_s=time.perf_counter() - start)
    return str(out_dir)


# Truth sides of the error-vs-runtime campaign: fixed settings whatever the case's options say.

TRUTH_FE = {"mesh_size_mm": 1.0, "degree": 2}  # the FE slab, P2 at 1.0 mm (71 k DOFs on the ideal ankle)
TRUTH_STEPS = 128


def _run_fe_truth(scene_ref: str, overrides: dict[str, Any], out_dir: Path, options: dict[str, Any]) -> str:
    """The FE slab at TRUTH_FE on the scene's own geometry mesh (a geometry.mesh_size_mm override
    of the case, which sweeps the springs, never reaches it: ``ignores_overrides``), ignoring the
    case's options."""
    return _run_fe("slab")(scene_ref, overrides, out_dir, dict(TRUTH_FE))


def resample_load(overrides: dict[str, Any], n_steps: int) -> dict[str, Any]:
    """The overrides with the load history load.time_s / load.force_n linearly re-sampled at
    n_steps equal increments of the same time span."""
    times = np.asarray(overrides["load.time_s"], dtype=float)
    forces = np.asarray(overrides["load.force_n"], dtype=float).reshape(len(times), 3)
    new_t = np.linspace(times[0], times[-1], n_steps + 1)
    new_f = np.stack([np.interp(new_t, times, forces[:, j]) for j in range(3)], axis=1)
    return {**overrides, "load.time_s": new_t.tolist(), "load.force_n": new_f.tolist()}


def _run_edem_truth(scene_ref: str, overrides: dict[str, Any], out_dir: Path, options: dict[str, Any]) -> str:
    """EDEM over the case's load history (load.time_s / load.force_n overrides) re-sampled at
    TRUTH_STEPS equal increments."""
    if "load.time_s" not in overrides or "load.force_n" not in overrides:
        raise InputError("the edem-128-steps side needs a load history", key="overrides", expected="load.time_s and load.force_n overrides")
    return _run_discrete("edem")(scene_ref, resample_load(overrides, TRUTH_STEPS), out_dir, options)


_run_fe_truth.modules = FE_MODULES
_run_fe_truth.reads_options = ()
_run_fe_truth.ignores_overrides = DEM_ONLY_OVERRIDES + ("geometry.mesh_size_mm",)
_run_fe_truth.shared = True
_run_edem_truth.modules = DISCRETE_MODULES
_run_edem_truth.reads_options = ("frames",)

SIDES: dict[str, SideRunner] = {
    "edem": _run_discrete("edem"),
    "dem": _run_discrete("dem"),
    **{f"fe-{model}": _run_fe(model) for model in FE_MODELS},
    **{f"fe-problem:{name}": _run_fe_problem(name) for name in FE_PROBLEMS},
    "fe-slab-truth": _run_fe_truth,
    "edem-128-steps": _run_edem_truth,
}
CLOSED_FORM_PREFIX = "closed-form:"


def side_names() -> list[str]:
    """Every side a case may name (closed forms as closed-form:<name>)."""
    return list(SIDES) + [CLOSED_FORM_PREFIX + name for name in (*CLOSED_FORMS, *FE_PROBLEMS)]


def side_modules(side: str) -> tuple[str, ...]:
    """The modules whose source (with what they import) the side's results depend on."""
    if side.startswith(CLOSED_FORM_PREFIX):
        return FE_EXACT_MODULES if side[len(CLOSED_FORM_PREFIX):] in FE_PROBLEMS else CLOSED_FORM_MODULES
    return getattr(SIDES.get(side), "modules", ANY_MODULES)


def side_inputs(side: str, overrides: dict[str, Any], options: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """The overrides and options ``side`` receives from :func:`run_side`: without the override
    keys its runner declares it ignores (``ignores_overrides``), and only the options it declares
    it reads (``reads_options``; a runner that does not say gets them all). What a shared side's
    result depends on besides code and scene files is exactly this pair (its cache key hashes it)."""
    runner = SIDES.get(side)
    ignored = getattr(runner, "ignores_overrides", ())
    read = getattr(runner, "reads_options", None)
    kept = {k: v for k, v in overrides.items() if k not in ignored}
    return kept, dict(options) if read is None else {k: v for k, v in options.items() if k in read}


def is_shared_side(side: str) -> bool:
    """Whether cases that give ``side`` the same inputs (:func:`side_inputs`) share one run of it
    (the FE references: minutes each; verification.runner's side store)."""
    return bool(getattr(SIDES.get(side), "shared", False))


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
        overrides, options = side_inputs(side, overrides or {}, options or {})
        overrides = expand_array_overrides(scene_ref, overrides) if overrides else {}
        if side.startswith(CLOSED_FORM_PREFIX):
            _run_closed_form(scene_ref, overrides, out, options, side[len(CLOSED_FORM_PREFIX) :])
        else:
            SIDES[side](scene_ref, overrides, out, options)
    except ResultWriteError as exc:  # disk full...: not the case's outcome, run it again
        return SideOutcome(side, ERROR, None, str(exc), time.perf_counter() - start, type(exc).__name__)
    except (InputError, SolverError) as exc:
        return SideOutcome(side, REFUSED, None, str(exc), time.perf_counter() - start, type(exc).__name__)
    except UnavailableError as exc:
        return SideOutcome(side, UNAVAILABLE, None, str(exc), time.perf_counter() - start, "UnavailableError")
    except Exception as exc:  # a bug: keep the traceback for the report, never crash the campaign
        text = "".join(traceback.format_exception_only(type(exc), exc)).strip()
        tail = traceback.format_exc().strip().splitlines()[-6:]
        return SideOutcome(side, ERROR, None, text + "\n" + "\n".join(tail), time.perf_counter() - start, type(exc).__name__)
    return SideOutcome(side, OK, str(out), "", time.perf_counter() - start)
