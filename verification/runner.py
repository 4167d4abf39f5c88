"""Run a campaign: cases in parallel processes (or on a Dask cluster), cached by their inputs.

Each case runs in ``OUT/cases/<case>/``: one result directory (docs/result-format.md) per side (``a-<side>``,
``b-<side>``) and ``metrics.json`` (every metric, the tolerance verdicts, wall times, the result
directories). The case is cached under a key hashing its definition, the scene file and every
file it references, the package version, the versions of the numerical libraries
(:func:`library_versions`) and the source of the modules that compute it: those its sides name
(:func:`verification.sides.side_modules`) and the metrics, with everything they import, plus the
files of this runner and of the side runners. Re-running an unchanged case only re-reads its
metrics.json; a change to code it uses or a library upgrade invalidates it, a change elsewhere
(another campaign, a report) does not. A cached case is used only when its metrics.json (written
last, atomically) is there and every side's result directory verifies against its manifest;
anything missing, truncated or changed makes the case run again. Verdicts are re-judged on every
run, so changing a tolerance needs no re-run.

The FE references are shared between cases (:func:`verification.sides.is_shared_side`): such a
side runs once per *side key* (:func:`side_key`: the side, the scene files, the overrides and
options the side receives (:func:`verification.sides.side_inputs`, so not the discrete bed's own
keys such as ``cartilage.coupling``), the versions and the source of the side's modules) into
``OUT/sides/<side>-<key>/`` (the sealed result directory ``result/``, then ``outcome.json``,
written last), under a lock of that entry; every case that needs it gets a copy in its own
directory, so a case stays self-contained and verifies by its own manifests. A store entry is
reused only when its outcome.json names the same key and its result verifies against its
manifest; the coupled and independent-spring cases of one point, or DEM and EDEM against one
FE slab, run the FE once, and a change to the discrete code only re-runs the discrete sides.
The first case of each side key is started first, so parallel workers rarely wait on an entry.

One campaign at a time writes a directory (a lock), workers die with the campaign, and Ctrl-C
stops it keeping every finished case (:mod:`verification.campaign_safety`). ``OUT/metrics.json``
gathers the campaign; the HTML report is drawn by the caller (``edem verify`` passes :func:`reports.html.write_campaign_report`).

After the cases, the campaign's analyses (:mod:`verification.analyses`: observed orders, the
thesis's figures beside ours, parameter sensitivities) are computed from their metrics; they are
cheap and never cached.

Each case ends in one verdict of :mod:`verification.verdicts` (verified, flagged, refused as
declared, ran; failed, error, unavailable), from its tolerances and the basis of each. Exit
status of a campaign (docs/campaigns.md#verdicts): 0 unless a case failed or crashed or a judged analysis failed (an
observed order below its minimum); flagged cases (outside a declared model band) and cases whose
side is unavailable (FE reference not installed) are reported and do not fail the campaign.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import dataclasses
import datetime as _dt
import fcntl
import hashlib
import importlib.metadata
import importlib.util
import json
import math
import multiprocessing
import os
import platform
import re
import shutil
import sys
import textwrap
import time
import traceback
from collections.abc import Callable, Iterable, Iterator
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from edem.atomic_dirs import manifest_problems
from geometries.errors import InputError
from edem.resultdir import non_finite_count, read_result_dir
from edem.scene import apply_overrides, read_scene_toml, resolve_scene_path
from verification import sources
from verification.analyses import format_analysis, run_analysis
from verification.bed_compliance import BED_COMPLIANCE_METRICS, add_bed_compliance, bed_compliance_of_run
from verification.campaign_model import Campaign, Case, validate_campaign
from verification.campaign_safety import CampaignInterrupted, campaign_lock, init_worker, sigint_blocked, stop_children
from verification.fe_analytic import FE_PROBLEMS, half_width_errors
from verification.fe_convergence import FE_VALUE_METRICS, fe_relative_error, fe_values
from verification.metrics import (
    COMPARISON_METRICS,
    COP_METRICS,
    SERIES_METRICS,
    compare_result_dirs,
    cop_metrics,
    matching_time_points,
    reference_series,
    series_metrics,
    with_regularised_peak,
)
from verification.sides import is_shared_side, run_side, side_inputs, side_modules
from verification.status import ERROR, FAILED, FLAGGED, OK, REFUSED, UNAVAILABLE
from verification.verdicts import case_verdict, count_verdicts, headline, tolerance_verdicts


#: where the hashed sources are read (a test points it at a copy)
SOURCE_ROOT = sources.ROOT
#: the glue every case runs through: their own source is hashed (what they import, per side)
CASE_GLUE_MODULES = ("verification.runner", "verification.sides", "verification.fe_analytic")
#: what computes the metrics of every case (hashed with everything it imports)
METRIC_MODULES = ("verification.metrics", "verification.bed_compliance", "edem.resultdir")
#: the glue a shared side runs through (its own source; the side's modules are hashed with all they import)
SIDE_GLUE_MODULES = ("verification.sides",)
#: the shared sides' store, under the campaign directory
SIDE_STORE = "sides"


# ---------------------------------------------------------------------------------------------
# JSON helpers


def json_safe(value: Any) -> Any:
    """numpy scalars/arrays to Python, non-finite floats to the strings "inf", "-inf", "nan"."""
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist())
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, (float, np.floating)):
        v = float(value)
        if math.isfinite(v):
            return v
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf")
    return value


def as_float(value: Any) -> float:
    """A metric value read back from JSON ("inf" strings included)."""
    return float(value)


def write_json(path: Path, data: Any) -> None:
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(json_safe(data), indent=2) + "\n", encoding="utf-8")
    os.replace(tmp, path)


# ---------------------------------------------------------------------------------------------
# Cache keys


def _source_digest(modules: tuple[str, ...]) -> str:
    """sha256 of the source of ``modules`` (a package name: all its modules)."""
    return sources.source_digest(modules, SOURCE_ROOT)


@lru_cache(maxsize=1)
def _package_version() -> str:
    """The installed edem version (read once: importlib.metadata parses the package's metadata
    file on every call, which was most of a case key's cost)."""
    try:
        return importlib.metadata.version("edem")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


def referenced_files(scene_path: Path, overrides: dict[str, Any]) -> list[Path]:
    """Files a scene reads besides itself: mesh files of [geometry], load and kinematics files."""
    try:
        data = read_scene_toml(scene_path)
    except InputError:
        return []
    apply_overrides(data, dict(overrides))
    files = []
    for section, keys in (("geometry", ("mobile", "fixed", "mobile_bone", "fixed_bone")), ("load", ("file",)), ("kinematics", ("file",))):
        table = data.get(section, {})
        if isinstance(table, dict):
            files += [scene_path.parent / table[k] for k in keys if isinstance(table.get(k), str)]
    return files


def _input_digest(definition: dict[str, Any], roots: Iterable[str], glue: tuple[str, ...], scene_ref: str, overrides: dict[str, Any]) -> str:
    """sha256 of a definition, the versions, the source of ``roots`` with all they import and of
    ``glue``, and the scene file with every file it references."""
    digest = hashlib.sha256()
    digest.update(json.dumps(json_safe(definition), sort_keys=True).encode())
    digest.update(_package_version().encode())
    digest.update(json.dumps(library_versions(), sort_keys=True).encode())
    digest.update(sources.closure_digest(tuple(sorted(set(roots))), SOURCE_ROOT).encode())
    digest.update(_source_digest(glue).encode())
    try:
        scene_path = resolve_scene_path(scene_ref)
        files = [scene_path] + referenced_files(scene_path, overrides)
    except InputError:
        files = []
    for path in files:
        digest.update(str(path.name).encode())
        digest.update(path.read_bytes() if path.is_file() else b"<missing>")
    return digest.hexdigest()


def case_key(case: Case) -> str:
    """sha256 of everything a case's results depend on (module docstring)."""
    roots = METRIC_MODULES + tuple(m for side in case.sides for m in side_modules(side))
    return _input_digest(case.definition(), roots, CASE_GLUE_MODULES, case.scene_ref(), case.overrides)


def side_key(case: Case, index: int) -> str | None:
    """sha256 of everything the case's side ``index`` computes from, when that side is shared
    (None otherwise): the side, the scene, the overrides and options it receives
    (:func:`verification.sides.side_inputs`), the versions, the source of its modules with all
    they import and of the glue that runs it (verification.sides), the scene files. Not the case's
    name, its other side, its metrics: cases equal in these share the side's run."""
    side = case.sides[index]
    if not is_shared_side(side):
        return None
    overrides, options = side_inputs(side, case.overrides, case.options)
    definition = {"side": side, "scene": case.scene, "overrides": overrides, "options": options}
    return _input_digest(definition, side_modules(side), SIDE_GLUE_MODULES, case.scene_ref(), overrides)


# ---------------------------------------------------------------------------------------------
# One case (runs in a worker process or on a Dask worker)


def _side_dir_name(index: int, side: str) -> str:
    return ("a", "b")[index] + "-" + re.sub(r"[^A-Za-z0-9_.-]+", "-", side)


def _thickness_metrics(a_dir: str, b_dir: str | None) -> dict[str, float]:
    """Mean and sd of a's ray-cast spring lengths; errors against the closed form's thickness."""
    a = read_result_dir(a_dir)
    frame = a.frame(0)
    hit = (frame.cell_data.get("ray_hit", np.ones(frame.triangles.shape[0])) > 0) & (frame.areas_mm2 > 0)
    lengths = frame.cell_data["spring_length_mm"][hit]
    out = {"thickness_mean_mm": float(lengths.mean()), "thickness_sd_mm": float(lengths.std())}
    if b_dir is not None:
        form = read_result_dir(b_dir).summary.get("closed_form", {})
        if "thickness_mm" in form:
            error = abs(out["thickness_mean_mm"] - form["thickness_mm"])
            out["thickness_mean_rel_error"] = error / form["thickness_mm"]
            bound = form.get("faceting_bound_mm", 0.0)
            out["thickness_faceting_ratio"] = error / bound if bound > 0 else (0.0 if error == 0 else math.inf)
    return out


def _stability_metrics(case: Case, a: dict[str, Any], wanted: set[str]) -> dict[str, float]:
    """outcome_mismatch, non_finite_outputs and force_residual_rel, those of ``wanted`` only
    (counting non-finite values reads every pressure map: a grid of hundreds of runs that
    only checks its outcome need not)."""
    out: dict[str, float] = {}
    actual = {OK: "converges", REFUSED: "refused"}.get(a["status"], a["status"])
    if case.expect is not None:
        matched = actual == case.expect.outcome
        if matched and actual == "refused" and case.expect.message:
            matched = re.search(case.expect.message, a["message"]) is not None
        if matched and actual == "converges" and case.expect.warning:
            warnings = read_result_dir(a["result_dir"]).summary.get("warnings", [])
            matched = any(re.search(case.expect.warning, str(w)) for w in warnings)
        out["outcome_mismatch"] = 0.0 if matched else 1.0
    if a["status"] == OK:
        if "non_finite_outputs" in wanted:
            out["non_finite_outputs"] = float(non_finite_count(a["result_dir"]))
        if "force_residual_rel" in wanted:
            result = read_result_dir(a["result_dir"])
            series = result.timeseries
            load = max(max(abs(series[f"force_{x}_n"]).max() for x in "xyz"), 1e-12)
            out["force_residual_rel"] = float(result.summary.get("max_force_residual_n", math.inf)) / load
    elif a["status"] == REFUSED:
        out["non_finite_outputs"] = 0.0  # nothing written
    return out


def _series_metrics(wanted: set[str], a: dict[str, Any], b: dict[str, Any] | None) -> dict[str, float]:
    """a_* / b_* summaries of each side's time series, and a_at_b_* of a's at b's time points."""
    regularised = any(m.endswith("regularised_peak_pressure_mpa") for m in wanted)  # it reads every map: only when asked
    read: dict[int, dict[str, Any]] = {}

    def series(side: dict[str, Any]) -> dict[str, Any]:
        if id(side) not in read:  # each side's directory read (and verified) once
            result = read_result_dir(side["result_dir"])
            values = reference_series(read_result_dir(a["result_dir"]), result)[0] if side is b and a["status"] == OK else result.timeseries
            read[id(side)] = with_regularised_peak(values, result) if regularised else values  # b as the comparison sees it (on M against springs)
        return read[id(side)]

    out: dict[str, float] = {}
    if wanted & set(COP_METRICS) and a["status"] == OK:
        out.update(cop_metrics(series(a)))
    if wanted & {f"{p}_{n}" for p in "ab" for n in SERIES_METRICS}:
        for prefix, side in (("a_", a), ("b_", b)):
            if side is not None and side["status"] == OK:
                out.update(series_metrics(series(side), prefix))
    if b is not None and a["status"] == b["status"] == OK and wanted & {f"a_at_b_{n}" for n in SERIES_METRICS}:
        sa, sb = series(a), series(b)
        same = sa["time_s"].shape == sb["time_s"].shape and np.allclose(sa["time_s"], sb["time_s"], rtol=1e-9, atol=1e-12)
        index = list(range(len(sa["time_s"]))) if same else matching_time_points(sa["time_s"], sb["time_s"])
        if index is not None:
            out.update(series_metrics({k: v[index] for k, v in sa.items()}, "a_at_b_"))
    return out


def compute_metrics(case: Case, sides: list[dict[str, Any]]) -> tuple[dict[str, float], dict[str, Any] | None]:
    """The case's metrics from its side outcomes (only those it declares) and the comparison."""
    wanted = set(case.metrics)
    metrics: dict[str, float] = {}
    comparison = None
    a = sides[0]
    b = sides[1] if len(sides) > 1 else None
    if wanted & {"outcome_mismatch", "non_finite_outputs", "force_residual_rel"}:
        metrics.update(_stability_metrics(case, a, wanted))
    both = a["status"] == OK and b is not None and b["status"] == OK
    if both and wanted & set(COMPARISON_METRICS):
        comparison = compare_result_dirs(a["result_dir"], b["result_dir"])
        metrics.update(comparison["metrics"])
    if comparison is not None and wanted & set(BED_COMPLIANCE_METRICS):
        metrics.update(add_bed_compliance(comparison, bed_compliance_of_run(a["result_dir"], b["result_dir"])))
    if a["status"] == OK and wanted & {"thickness_mean_mm", "thickness_sd_mm", "thickness_mean_rel_error", "thickness_faceting_ratio"}:
        metrics.update(_thickness_metrics(a["result_dir"], b["result_dir"] if both else None))
    metrics.update(_series_metrics(wanted, a, b))
    if a["status"] == OK and wanted & set(FE_VALUE_METRICS):
        metrics.update(fe_values(a["result_dir"]))
    if both and wanted & {"half_width_rel_error", "half_width_fit_rel_error"}:
        metrics.update(half_width_errors(read_result_dir(a["result_dir"]).summary, read_result_dir(b["result_dir"]).summary))
    return {k: v for k, v in metrics.items() if k in wanted}, comparison


def _scene_description(case: Case) -> str:
    if case.scene.startswith("fe-problem:"):
        return FE_PROBLEMS.get(case.scene.split(":", 1)[1], "")
    try:
        data = read_scene_toml(resolve_scene_path(case.scene_ref()))
        return " ".join(str(data.get("scene", {}).get("description", "")).split())
    except InputError:
        return ""


@contextlib.contextmanager
def _entry_lock(path: Path) -> Iterator[None]:
    """An exclusive flock on ``path`` (blocking): one worker computes a store entry, the others
    wait for it and then reuse it. The kernel drops it when its holder dies."""
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


def _stored_outcome(entry: Path, key: str) -> dict[str, Any] | None:
    """The outcome of a complete store entry for ``key`` (its result verifying), else None."""
    try:
        outcome = json.loads((entry / "outcome.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(outcome, dict) or outcome.get("key") != key or outcome.get("status") not in (OK, REFUSED):
        return None  # a crash or an unavailable FE is never stored: it runs again
    if outcome["status"] == OK and manifest_problems(entry / "result"):
        return None  # a result file missing, changed or added since it ran
    return outcome


def _shared_side(case: Case, index: int, key: str, store: Path, target: Path) -> dict[str, Any]:
    """The outcome of a shared side: taken from the store entry of ``key`` or computed into it
    (under the entry's lock), its result directory copied to ``target``. "shared" names the
    entry, "reused" says whether this case found it done."""
    side = case.sides[index]
    entry = store / f"{_side_dir_name(index, side)[2:]}-{key[:24]}"
    store.mkdir(parents=True, exist_ok=True)
    with _entry_lock(entry.with_name(entry.name + ".lock")):
        outcome = _stored_outcome(entry, key)
        reused = outcome is not None
        if outcome is None:
            if entry.exists():
                shutil.rmtree(entry)  # an interrupted or stale run of this entry
            entry.mkdir()
            outcome = run_side(side, case.scene_ref(), dict(case.overrides), entry / "result", dict(case.options)).to_dict()
            if outcome["status"] in (OK, REFUSED):
                outcome.update(key=key, result_dir="result" if outcome["result_dir"] else None)
                write_json(entry / "outcome.json", outcome)  # last: the entry is complete
        if outcome["status"] == OK:
            shutil.copytree(entry / "result", target)
    outcome = {k: v for k, v in outcome.items() if k != "key"}
    outcome.update(result_dir=str(target) if outcome["status"] == OK else None, shared=entry.name, reused=reused)
    return outcome


def execute_case(case: Case, case_dir: str, key: str, side_keys: tuple[str | None, ...] = ()) -> dict[str, Any]:
    """Run a case's sides into ``case_dir`` and write its metrics.json (without verdicts).

    Top-level and picklable: runs in a ProcessPoolExecutor worker or on a Dask worker. A side
    refused as the case expects skips the reference side. ``side_keys``: per side, its
    :func:`side_key` (None: not shared); a shared side comes from the campaign's side store
    (``case_dir/../../sides``), computed there once. Never raises for a solver problem: crashes
    become the "error" outcome with their traceback.
    """
    start = time.perf_counter()
    root = Path(case_dir)
    if root.exists():
        shutil.rmtree(root)
    root.mkdir(parents=True)
    store = root.parent.parent / SIDE_STORE
    sides: list[dict[str, Any]] = []
    for index, side in enumerate(case.sides):
        if index and sides[0]["status"] != OK:
            break  # no point running the reference of a refused or failed subject
        target = root / _side_dir_name(index, side)
        shared = side_keys[index] if index < len(side_keys) else None
        if shared is None:
            sides.append(run_side(side, case.scene_ref(), dict(case.overrides), target, dict(case.options)).to_dict())
        else:
            sides.append(_shared_side(case, index, shared, store, target))
    record: dict[str, Any] = {"case": case.definition(), "key": key, "sides": sides, "metrics": {}, "comparison": None}
    try:
        if not any(s["status"] in (UNAVAILABLE, ERROR) for s in sides):
            record["metrics"], record["comparison"] = compute_metrics(case, sides)
    except Exception as exc:  # a bug in the metrics: report it with the case

        sides.append({"side": "metrics", "status": ERROR, "result_dir": None, "message": f"{type(exc).__name__}: {exc}\n" + traceback.format_exc()[-1500:], "wall_time_s": 0.0, "error_type": type(exc).__name__})
    record["scene_description"] = _scene_description(case)
    record["wall_time_s"] = time.perf_counter() - start
    record["computed_at"] = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    record["host"] = platform.node()
    for side in sides:
        if side.get("result_dir"):
            side["result_dir"] = str(Path(side["result_dir"]).relative_to(root))
    write_json(root / "metrics.json", record)
    return json.loads((root / "metrics.json").read_text(encoding="utf-8"))


# ---------------------------------------------------------------------------------------------
# Verdicts


def judge(case: Case, record: dict[str, Any], fe_errors: dict[str, float] | None = None) -> tuple[str, dict[str, dict[str, Any]]]:
    """The case's verdict (one of verification.verdicts.CASE_VERDICTS) and, per tolerance, its
    value, tolerance, basis (kind and reason) and verdict (verification.verdicts.tolerance_verdicts).
    ``fe_errors``: the FE reference's estimated relative error per metric (default: the case's
    ``fe_errors``, else the stored mesh-convergence study's estimate for its FE run,
    verification.fe_convergence.fe_relative_error; none known when neither has one)."""
    statuses = [s["status"] for s in record["sides"]]
    refused_as_declared = case.expect is not None and case.expect.outcome == "refused" and record["metrics"].get("outcome_mismatch") == 0.0
    if any(s == UNAVAILABLE for s in statuses):
        return UNAVAILABLE, {}
    metrics = {m: as_float(v) for m, v in record["metrics"].items() if m in case.tolerance}
    verdicts = tolerance_verdicts(metrics, case.tolerance, case.bases(), not_applicable=refused_as_declared,
                                  fe_errors=fe_errors if fe_errors is not None else (case.fe_errors or fe_relative_error(case)),
                                  fe_reference=len(case.sides) > 1 and case.sides[-1].startswith("fe-"))
    expected = None if case.expect is None else case.expect.outcome
    return case_verdict(statuses, verdicts, expected, refused_as_declared), verdicts


def outcome_of(record: dict[str, Any]) -> str:
    """converges / refused / unavailable / error, from side a."""
    status = record["sides"][0]["status"]
    return {OK: "converges", REFUSED: "refused"}.get(status, status)


def _cached_record(case_dir: Path, key: str) -> dict[str, Any] | None:
    path = case_dir / "metrics.json"
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if record.get("key") != key:
        return None
    statuses = [s["status"] for s in record.get("sides", [])]
    if not statuses or any(s in (UNAVAILABLE, ERROR) for s in statuses):
        return None  # availability may change and crashes get fixed: run those again
    if any(s.get("result_dir") and manifest_problems(case_dir / s["result_dir"]) for s in record["sides"]):
        return None  # a result file missing, changed or added since the case ran: run it again
    return record


# ---------------------------------------------------------------------------------------------
# The campaign


@lru_cache(maxsize=1)
def library_versions() -> dict[str, str]:
    """The versions in :func:`software_versions` that results depend on (not the host's platform
    string): part of every case's cache key, so an upgrade of numpy, gmsh, dolfinx... re-runs."""
    return {k: v for k, v in software_versions().items() if k != "platform"}


def software_versions() -> dict[str, str]:
    """Versions of Python and the numerical stack (dolfinx only if installed), without importing them."""
    versions = {"python": platform.python_version(), "platform": platform.platform()}
    for name in ("edem", "numpy", "scipy", "vtk", "pyvista", "matplotlib", "embreex", "gmsh", "meshio"):
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            pass
    if importlib.util.find_spec("dolfinx") is not None:
        dists = _distributions_of("dolfinx")
        for dist in dists + ["fenics-dolfinx"]:
            try:
                versions["dolfinx"] = f"{importlib.metadata.version(dist)} ({dist})"
                break
            except importlib.metadata.PackageNotFoundError:
                continue
    return versions


def _distributions_of(package: str) -> list[str]:
    """The names of the installed distributions that provide the top-level ``package``.

    Their top_level.txt answers in a tenth of a second; ``packages_distributions()`` infers the
    packages of every distribution from its file list, 3-8 s on the shared machine, once per
    campaign in the parent before any case starts. It is the fallback when no top_level.txt names
    the package (a distribution installed without one)."""
    named = [d.metadata["Name"] for d in importlib.metadata.distributions() if package in (d.read_text("top_level.txt") or "").split()]
    return named or importlib.metadata.packages_distributions().get(package, [])


Todo = tuple[Case, Path, str, tuple[str | None, ...]]  # case, its directory, its key, its side keys


def _first_of_each_side_first(todo: list[Todo]) -> list[Todo]:
    """``todo`` with the first case of each shared side key ahead of the cases that reuse it, so
    parallel workers compute different FE runs instead of one waiting on another's."""
    seen: set[str] = set()
    first, later = [], []
    for item in todo:
        keys = {k for k in item[3] if k}
        (later if keys & seen else first).append(item)
        seen |= keys
    return first + later


def limit_blas_threads() -> None:
    """One BLAS thread in this process, as edem.cli.main sets OPENBLAS_NUM_THREADS before numpy
    loads (its comment says why: OpenBLAS threads that find their core busy spin), for a Dask
    worker whose numpy is already loaded."""
    from threadpoolctl import threadpool_limits

    threadpool_limits(1, user_api="blas")


def _executor_results(
    todo: list[Todo], jobs: int, scheduler: str | None
) -> Iterable[tuple[Case, dict[str, Any]]]:
    """Yield (case, record) as cases finish: inline (jobs 1), a process pool or a Dask cluster."""
    if not todo:
        return
    if scheduler is not None:
        try:
            from dask.distributed import Client, as_completed
        except ImportError:
            raise InputError("--scheduler needs dask.distributed", key="--scheduler", expected="pip install 'dask[distributed]'") from None
        try:
            client = Client(scheduler, timeout="20s")
        except (OSError, TimeoutError, ValueError) as exc:
            raise InputError(f"cannot reach the Dask scheduler: {exc}", key="--scheduler", expected="the address of a running scheduler, e.g. tcp://host:8786") from None
        with client:
            client.run(limit_blas_threads)  # workers started by the user loaded numpy before edem could set the variable
            futures = {
                client.submit(execute_case, case, str(case_dir), key, shared, key=f"edem-case-{case.name}-{key[:12]}", pure=False): case
                for case, case_dir, key, shared in todo
            }
            for future in as_completed(futures):
                yield futures[future], future.result()
        return
    if jobs <= 1:
        for case, case_dir, key, shared in todo:
            yield case, execute_case(case, str(case_dir), key, shared)
        return
    context = multiprocessing.get_context("spawn")
    before = {p.pid for p in multiprocessing.active_children()}
    pool = concurrent.futures.ProcessPoolExecutor(
        max_workers=min(jobs, len(todo)), mp_context=context, initializer=init_worker, initargs=(os.getpid(),)
    )
    try:
        with sigint_blocked():  # the workers start (in submit) with SIGINT blocked until init_worker
            futures = {pool.submit(execute_case, case, str(case_dir), key, shared): case for case, case_dir, key, shared in todo}
        for future in concurrent.futures.as_completed(futures):
            yield futures[future], future.result()
    except BaseException:  # Ctrl-C, or the consumer stopped early: no worker goes on writing cases
        pool.shutdown(wait=False, cancel_futures=True)
        stop_children(before)
        raise
    pool.shutdown(wait=True)


def run_campaign(
    campaign: Campaign,
    out_dir: str | Path,
    *,
    jobs: int | None = None,
    scheduler: str | None = None,
    progress: bool | None = None,
    report: Callable[[dict[str, Any], Path], Path] | None = None,
    on_case: Callable[[str, bool], None] | None = None,
) -> dict[str, Any]:
    """Run (or take from the cache) every case of the campaign; write metrics.json.

    ``jobs``: worker processes (default: the CPU count; 1 runs in this process). ``scheduler``:
    the address of a Dask distributed scheduler to run the cases on instead (its workers must
    see ``out_dir``). ``progress``: a tqdm bar on stderr (default: when stderr is a terminal).
    ``on_case(name, cached)`` is called as each case is done. ``report(summary, out_dir)``, when
    given, draws the report (the caller passes it: reports are a higher layer, e.g.
    :func:`reports.html.write_campaign_report`) and returns its path. Returns the campaign summary
    (also in ``out_dir/metrics.json``), with "exit_status" and "report" (None without one).
    """
    validate_campaign(campaign)
    out = Path(out_dir)
    jobs = (os.cpu_count() or 1) if jobs is None else jobs
    if jobs < 1:
        raise InputError(f"--jobs {jobs}", key="--jobs", expected="a number of processes >= 1")
    with campaign_lock(out):
        return _run_campaign_locked(campaign, out, jobs, scheduler, progress, report, on_case)


def _run_campaign_locked(
    campaign: Campaign,
    out: Path,
    jobs: int,
    scheduler: str | None,
    progress: bool | None,
    report: Callable[[dict[str, Any], Path], Path] | None,
    on_case: Callable[[str, bool], None] | None,
) -> dict[str, Any]:
    (out / "cases").mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    records: dict[str, dict[str, Any]] = {}
    cached: dict[str, bool] = {}
    todo = []
    for case in campaign.cases:
        case_dir = out / "cases" / case.name
        key = case_key(case)
        record = _cached_record(case_dir, key)
        if record is None:
            todo.append((case, case_dir, key, tuple(side_key(case, i) for i in range(len(case.sides)))))
        else:
            records[case.name], cached[case.name] = record, True
    show = sys.stderr.isatty() if progress is None else progress
    bar = None
    if show:
        from tqdm import tqdm

        bar = tqdm(total=len(campaign.cases), desc=campaign.name, unit="case", file=sys.stderr, initial=len(records))
    for name in list(records):
        if on_case:
            on_case(name, True)
    finished = _executor_results(_first_of_each_side_first(todo), jobs, scheduler)
    try:
        for case, record in finished:
            records[case.name], cached[case.name] = record, False
            if bar is not None:
                bar.update(1)
            if on_case:
                on_case(case.name, False)
    except OSError as exc:  # the campaign directory cannot be written (disk full...)
        finished.close()
        raise InputError(f"cannot write the campaign's results ({exc.strerror or exc}); {len(records)} finished cases are kept",
                         file=out, expected="free space and a writable directory") from None
    except KeyboardInterrupt:
        finished.close()  # stops the workers
        raise CampaignInterrupted(
            f"interrupted: {len(records)} of {len(campaign.cases)} cases done and kept in {out / 'cases'}; "
            "the same command runs the rest"
        ) from None
    finally:
        if bar is not None:
            bar.close()

    case_rows = []
    for case in campaign.cases:
        record = records[case.name]
        status, verdicts = judge(case, record)
        if record.get("status") != status or record.get("verdicts") != json_safe(verdicts) or "tolerance" not in record:
            record.update(status=status, verdicts=verdicts, tolerance=case.tolerance, description=case.description)
            write_json(out / "cases" / case.name / "metrics.json", record)
        case_rows.append(
            {
                "name": case.name,
                "description": case.description,
                "scene": case.scene,
                "scene_description": record.get("scene_description", ""),
                "overrides": case.overrides,
                "sides": record["sides"],
                "status": status,
                "outcome": outcome_of(record),
                "expected_outcome": None if case.expect is None else case.expect.outcome,
                "metrics": record["metrics"],
                "tolerance": case.tolerance,
                "verdicts": verdicts,
                "params": case.params,
                "options": case.options,
                "maps": case.maps,
                "wall_time_s": record["wall_time_s"],
                "cached": cached[case.name],
                "case_dir": f"cases/{case.name}",
                "result_dirs": [f"cases/{case.name}/{s['result_dir']}" for s in record["sides"] if s.get("result_dir")],
                "out_dir": str(out),  # where result_dirs are, for an analysis that reads the fields (fe-convergence)
            }
        )
    counts = count_verdicts([r["status"] for r in case_rows])
    outcomes = {o: sum(1 for r in case_rows if r["outcome"] == o) for o in ("converges", "refused")}

    by_name = {r["name"]: r for r in case_rows}
    analyses = [run_analysis(analysis, by_name) for analysis in campaign.analyses]
    analyses_failed = sum(1 for a in analyses if a["status"] in (FAILED, ERROR))
    summary = {
        "campaign": campaign.name,
        "description": campaign.description,
        "out_dir": str(out),
        "finished_at": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "wall_time_s": time.perf_counter() - started,
        "cases_wall_time_s": sum(r["wall_time_s"] for r in case_rows),
        "computed": sum(1 for r in case_rows if not r["cached"]),
        "cached": sum(1 for r in case_rows if r["cached"]),
        "jobs": jobs if scheduler is None else None,
        "scheduler": scheduler,
        "counts": counts,
        "outcomes": outcomes,
        "exit_status": 1 if counts[FAILED] or counts[ERROR] or analyses_failed else 0,
        "versions": software_versions(),
        "figures": [dataclasses.asdict(figure) for figure in campaign.figures],
        "analyses": analyses,
        "cases": case_rows,
    }
    summary["report"] = None
    if report:
        summary["report"] = str(report(summary, out))
    write_json(out / "metrics.json", summary)
    return summary


def format_summary(summary: dict[str, Any]) -> str:
    """The text `edem verify` prints: the answer of a trust analysis first (the main job's ankle
    answer, in sentences), then counts, outcomes, a table of what failed, the flagged metrics and
    every analysis's table."""
    counts, outcomes = summary["counts"], summary["outcomes"]
    lines = []
    for result in summary.get("analyses") or ():
        if result.get("kind") == "trust":
            lines.append(f"{result['title']} [{result['status']}]")
            lines += [textwrap.fill(sentence, width=110, initial_indent="- ", subsequent_indent="  ", break_on_hyphens=False)
                      for sentence in result.get("values", {}).get("sentences", [])]
            lines.append("")
    lines += [
        f"{summary['campaign']}: {len(summary['cases'])} cases: {headline(counts)} ({summary['computed']} run, {summary['cached']} from the cache) "
        f"in {summary['wall_time_s']:.1f} s",
        f"outcomes: {outcomes['converges']} converge, {outcomes['refused']} refused",
    ]
    bad = [r for r in summary["cases"] if r["status"] in (FAILED, ERROR)]
    if bad:
        lines.append("")
        lines.append(f"{'case':34s} {'metric':26s} {'value':>12s} {'tolerance':>12s}")
        for row in bad:
            failing = [(m, v) for m, v in row["verdicts"].items() if v["verdict"] in ("fail", "missing")]
            if row["status"] == ERROR or not failing:
                message = next((s["message"] for s in row["sides"] if s["status"] in (ERROR, REFUSED)), "")
                lines.append(f"{row['name']:34s} {row['status']}: {message.splitlines()[0] if message else ''}")
            for metric, verdict in failing:
                value = "missing" if verdict["value"] is None else f"{verdict['value']:.4g}"
                lines.append(f"{row['name']:34s} {metric:26s} {value:>12s} {verdict['tolerance']:12.4g}")
                if verdict["value"] is None:
                    message = next((s["message"] for s in row["sides"] if s["status"] != OK), "")
                    if message:
                        lines.append(f"{'':34s}   ({message.splitlines()[0]})")
    flagged = [r for r in summary["cases"] if r["status"] == FLAGGED]
    if flagged:
        lines.append("")
        lines.append("flagged (outside a declared model band; reported, not a failure):")
        for row in flagged:
            for metric, verdict in row["verdicts"].items():
                if verdict["verdict"] == "outside band":
                    lines.append(f"  {row['name']:32s} {metric:26s} {verdict['value']:+12.4g} outside ±{verdict['tolerance']:.4g}")
    unavailable = [r for r in summary["cases"] if r["status"] == UNAVAILABLE]
    for row in unavailable:
        message = next(s["message"] for s in row["sides"] if s["status"] == UNAVAILABLE)
        lines.append(f"{row['name']}: {message}")
    if summary.get("analyses"):
        for result in summary["analyses"]:
            lines.append("")
            lines.append(format_analysis(result))
    return "\n".join(lines)
