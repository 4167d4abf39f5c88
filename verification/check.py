"""`edem check`: the regression gate against stored references (docs/campaigns.md#verdicts).

For a fixed set of scenes (:data:`CHECK_SCENES`: ideal and subject standing, ideal toe-off, the
flat plates) ``verification/references/<name>.json`` stores what EDEM computed when the
references were last refreshed (per time point: the regularised peak pressure, the raw peak,
contact area, displacement of G, and a coarse pressure field) and, when the FE reference was
available then, the FE slab's values of the same quantities. Each quantity has the definition of
summary.json and the campaigns (docs/method.md#7-comparison-metrics): the regularised peak is
:func:`edem.pressure_metrics.surface_regularised_peak_mpa` of each time point's pressure map (the
largest mean pressure over a 1 mm^2 disc; the raw peak does not converge at a contact rim, so it
is stored and reported only); the FE side is measured on M, where the springs live
(:func:`verification.metrics.reference_series`: its area, raw peak and pressure as force per area
of M), its pressure sampled at EDEM's spring ends and binned like EDEM's.

``edem check`` reruns EDEM on each scene and reports two things separately:

* **drift**: EDEM against its stored baseline, the magnitude of the relative change (largest over
  the time points) within :data:`EDEM_TOLERANCES` (the same code gives the same numbers): this is
  the gate, exit 1 with a table of what drifted;
* **model error**: EDEM against the stored FE values, when the reference holds them, signed as in
  the campaigns ((EDEM - FE) / |FE|, the displacement's |u - u_FE| / |u_FE| negative when EDEM's
  bone moves less; the field's L2 error is a norm; the value of largest magnitude over the time
  points), beside the declared model band (:data:`verification.verdicts.MODEL_BAND_REL`):
  reported, flagged beyond the band, never a failure (it measures the spring bed, not a change of
  the code). The raw peak's error is printed "reported, not judged".

Exit 0 without drift (2 on bad input: a missing or unreadable reference file). ``edem check --refresh`` recomputes and rewrites the references (FE included
when :func:`verification.sides.fe_availability` says it can run; FE rows say "FE reference not
available" otherwise). ``--refresh --no-fe`` keeps the stored FE values (and says so), or
refuses when they are for other time points; an FE run that fails during a refresh says that it
dropped them. ``--references DIR`` points at another directory (tests use a copy).

A reference that is incomplete (a quantity missing, null or not one finite value per time
point; ``"fe": null`` without a stored reason ``fe_unavailable``) or of another format version
(:data:`FORMAT_VERSION`; version 1 stored the raw peak only) is bad input (exit 2) naming the
file and the key, never a pass that skipped the comparison.

Coarse pressure field: each spring's pressure, weighted by its area, is binned into cubes of
:data:`FIELD_VOXEL_MM` by the spring centroid at the mobile body's initial pose (mean pressure
per cube: the contact force in the cube over the spring area in it); two fields are compared
by the L2 relative error over the union of their cubes. The FE pressure (force per area of M) is
sampled at the far end of each spring (where the FE slab's contact face lies) and binned by the
same centroids.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import os
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from geometries.errors import InputError
from edem.pressure_metrics import PRESSURE_ON_MOBILE, surface_regularised_peak_mpa
from edem.resultdir import read_result_dir
from edem.results import write_results
from edem.scene import load_scene
from edem.solver import run
from verification.campaign_model import SCENES_DIR, THESIS_ANKLE
from verification.metrics import (
    displacement_error,
    l2_relative_error,
    largest_magnitude,
    pressure_at_cells,
    project_onto_surface,
    reference_series,
    relative_error,
    signed_relative_error,
)
from verification.runner import json_safe, software_versions
from verification.sides import OK, fe_availability, run_side


REFERENCES_DIR = Path(__file__).resolve().parent / "references"
FIELD_VOXEL_MM = 2.0
#: 2: the regularised peak per time point and the FE measured on M (1: the raw peak only, the FE on its own face)
FORMAT_VERSION = 2


@dataclass(frozen=True)
class CheckScene:
    """One scene of the gate: a built-in name or a TOML of verification/scenes/, with overrides."""

    name: str
    scene: str
    overrides: dict[str, Any] = field(default_factory=dict)
    fe_model: str = "slab"

    def scene_ref(self) -> str:
        return str(SCENES_DIR / self.scene) if self.scene.endswith(".toml") else self.scene


#: the ankles on the thesis's geometry and threshold law (THESIS_ANKLE), which the stored FE slab
#: values are the twin of (the scenes' default, the gap law on measured layers, has no FE twin
#: yet). The thesis's toe-off on the coupled layer passes 2 springs (0.16 % of those in contact)
#: through the plafond at the contact's rim: the gate keeps that baseline ([solver]
#: allow_bone_overlap), as it was stored, with its warning
CHECK_SCENES = (
    CheckScene("ideal-standing", "ideal-standing", dict(THESIS_ANKLE)),
    CheckScene("subject-standing", "subject-standing", dict(THESIS_ANKLE)),
    CheckScene("ideal-toe-off", "ideal-toe-off", {**THESIS_ANKLE, "solver.allow_bone_overlap": True}),
    CheckScene("flat-plates", "flat-plates.toml"),
)

#: EDEM against its stored baseline: the same code gives the same numbers to round-off; the
#: contact area and the binned field may move by a borderline spring (~0.1 % of the area).
EDEM_TOLERANCES = {
    "regularised_peak_pressure_mpa": 1e-6,
    "peak_pressure_mpa": 1e-6,
    "contact_area_mm2": 2e-3,
    "displacement_mm": 1e-6,
    "pressure_field": 2e-3,
}
QUANTITIES = tuple(EDEM_TOLERANCES)
#: compared with the FE but not judged against the band: the raw peak of a sharp contact edge does
#: not converge under mesh refinement (edem.pressure_metrics); the regularised peak is judged
REPORTED_ONLY = ("peak_pressure_mpa",)
#: errors that are norms, not signed (the field's L2 relative error)
UNSIGNED = ("pressure_field",)
DRIFT, FLAGGED = "DRIFT", "flagged"


# ---------------------------------------------------------------------------------------------
# Quantities of a result directory


def coarse_field(centroids_mm: np.ndarray, areas_mm2: np.ndarray, pressure_mpa: np.ndarray, voxel_mm: float = FIELD_VOXEL_MM) -> dict[str, Any]:
    """Area-weighted mean pressure per cube of ``voxel_mm`` (cubes indexed by floor(x / voxel))."""
    keep = areas_mm2 > 0
    cells = np.floor(centroids_mm[keep] / voxel_mm).astype(np.int64)
    unique, inverse = np.unique(cells, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    force = np.bincount(inverse, weights=pressure_mpa[keep] * areas_mm2[keep], minlength=len(unique))
    area = np.bincount(inverse, weights=areas_mm2[keep], minlength=len(unique))
    return {"voxel_mm": voxel_mm, "cells": unique.tolist(), "pressure_mpa": (force / area).tolist()}


def field_difference(field: dict[str, Any], reference: dict[str, Any]) -> float:
    """L2 relative error of a coarse field against a reference one over the union of their cubes."""
    if not math.isclose(field["voxel_mm"], reference["voxel_mm"]):
        raise InputError("coarse fields on different cubes", key="pressure_field", expected=f"voxel_mm = {reference['voxel_mm']}")
    values: dict[tuple[int, ...], list[float]] = {}
    for cell, p in zip(reference["cells"], reference["pressure_mpa"]):
        values.setdefault(tuple(cell), [0.0, 0.0])[1] = float(p)
    for cell, p in zip(field["cells"], field["pressure_mpa"]):
        values.setdefault(tuple(cell), [0.0, 0.0])[0] = float(p)
    pairs = np.array(list(values.values()), dtype=np.float64).reshape(-1, 2)

    return l2_relative_error(pairs[:, 0], pairs[:, 1])


def edem_quantities(result_dir: str | Path, scene) -> dict[str, Any]:
    """Per time point: regularised and raw peak pressure, contact area, displacement of G and the
    coarse field of an EDEM result directory of ``scene`` (binned by the spring centroids at M's
    initial pose)."""
    result = read_result_dir(result_dir)
    centroids, areas = scene.mobile.centroids_mm, scene.mobile.areas_mm2  # the frames' triangles, in order
    frames = [result.frame(k) for k in range(len(result.time_s))]
    fields = [coarse_field(centroids, areas, pressure_at_cells(frame)) for frame in frames]
    return _quantities(result.timeseries, frames, fields)


def fe_quantities(fe_dir: str | Path, edem_dir: str | Path, scene) -> dict[str, Any]:
    """The FE result's quantities per time point, measured as the campaigns compare it with EDEM
    (:func:`verification.metrics.reference_series`: on M, where the springs live, when the FE
    maps its contact face onto M); its pressure sampled at the far end of each EDEM spring at M's
    initial pose (centroid + length x normal: where the FE slab's contact face is; the FE's
    surface is built at that pose) and binned like EDEM's."""
    fe, edem = read_result_dir(fe_dir), read_result_dir(edem_dir)
    series, on_mobile = reference_series(edem, fe)
    pressure_key = PRESSURE_ON_MOBILE if on_mobile else "pressure_mpa"
    centroids, normals, areas = scene.mobile.centroids_mm, scene.mobile.unit_normals, scene.mobile.areas_mm2
    frames, fields = [], []
    for k in range(len(fe.time_s)):
        frame_fe = fe.frame(k)
        length = edem.frame(k).cell_data.get("spring_length_mm", np.zeros(len(centroids)))
        proj = project_onto_surface(frame_fe.points_mm, frame_fe.triangles, centroids + length[:, None] * normals)
        if pressure_key in frame_fe.point_data:
            p = np.einsum("ij,ij->i", proj.barycentric, frame_fe.point_data[pressure_key][frame_fe.triangles[proj.triangle]])
        else:
            p = frame_fe.cell_data["pressure_mpa"][proj.triangle]
        frames.append(frame_fe)
        fields.append(coarse_field(centroids, areas, p))
    return {
        **_quantities(series, frames, fields),
        "measured_on": "M (area and pressure as force per area of M)" if on_mobile else "the FE's own contact face",
        "summary": {k: fe.summary[k] for k in ("method", "n_dofs", "wall_time_s", "warnings") if k in fe.summary},
    }


def _quantities(series: dict[str, np.ndarray], frames: list, fields: list) -> dict[str, Any]:
    """The stored quantities per time point of a docs/campaigns.md#verdicts time series, its
    pressure maps (the regularised peak of each, as summary.json's) and its binned fields."""
    return {
        "time_s": series["time_s"].tolist(),
        "regularised_peak_pressure_mpa": [surface_regularised_peak_mpa(frame) for frame in frames],
        "peak_pressure_mpa": np.asarray(series["peak_pressure_mpa"], float).tolist(),
        "contact_area_mm2": np.asarray(series["contact_area_mm2"], float).tolist(),
        "displacement_mm": np.column_stack([series[f"disp_{x}_mm"] for x in "xyz"]).tolist(),
        "pressure_field": fields,
    }


def _same_time_points(values: dict[str, Any], reference: dict[str, Any]) -> None:
    if len(values["time_s"]) != len(reference["time_s"]) or not np.allclose(values["time_s"], reference["time_s"]):
        raise InputError("the scene's time points differ from the stored reference's", key="time_s", expected=f"{reference['time_s']} (edem check --refresh after a scene change)")


def drift(values: dict[str, Any], reference: dict[str, Any]) -> dict[str, float]:
    """Largest magnitude of the relative change over the time points of each quantity (a gate on
    |change|: |v - r| / |r|, Euclidean for the displacement, L2 for the field)."""
    _same_time_points(values, reference)
    out = {}
    for name in QUANTITIES:
        if name == "pressure_field":
            out[name] = max(field_difference(v, r) for v, r in zip(values[name], reference[name]))
        else:
            out[name] = max(relative_error(np.asarray(v), np.asarray(r)) for v, r in zip(values[name], reference[name]))
    return out


def model_errors(values: dict[str, Any], reference: dict[str, Any]) -> dict[str, float]:
    """Signed errors of EDEM against the FE (docs/method.md#7-comparison-metrics, as the campaigns'):
    (v - r) / |r| of the peaks and the area, the displacement's |u - u_r| / |u_r| negative when
    EDEM's bone moves less, the field's L2 error (a norm); each the value of largest magnitude
    over the time points."""
    _same_time_points(values, reference)
    out = {}
    for name in QUANTITIES:
        pairs = list(zip(values[name], reference[name]))
        if name == "pressure_field":
            out[name] = max(field_difference(v, r) for v, r in pairs)
        elif name == "displacement_mm":
            out[name] = largest_magnitude(displacement_error(np.asarray(v), np.asarray(r)) for v, r in pairs)
        else:
            out[name] = largest_magnitude(signed_relative_error(v, r) for v, r in pairs)
    return out


# ---------------------------------------------------------------------------------------------
# Running and storing


def _run_edem(check: CheckScene, out_dir: Path) -> tuple[dict[str, Any], Path, Any]:
    scene = load_scene(check.scene_ref(), dict(check.overrides))
    result_dir = write_results(run(scene, "edem"), out_dir / "edem")
    return edem_quantities(result_dir, scene), result_dir, scene


def refresh_reference(check: CheckScene, references: Path, *, with_fe: bool = True, log=print) -> dict[str, Any]:
    """Recompute and write ``references/<name>.json`` (FE values when the FE reference can run)."""
    with tempfile.TemporaryDirectory(prefix=f"edem-check-{check.name}-") as tmp:
        start = time.perf_counter()
        edem, edem_dir, scene = _run_edem(check, Path(tmp))
        data: dict[str, Any] = {
            "format": FORMAT_VERSION,
            "name": check.name,
            "scene": check.scene,
            "overrides": check.overrides,
            "refreshed_at": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            "versions": {k: v for k, v in software_versions().items() if k in ("python", "edem", "numpy", "scipy", "embreex", "dolfinx")},
            "edem": edem,
            "fe": None,
        }
        log(f"{check.name}: EDEM baseline in {time.perf_counter() - start:.1f} s")
        why = fe_availability() if with_fe else "FE reference not available: not requested (--no-fe)"
        if why is None:
            start = time.perf_counter()
            outcome = run_side(f"fe-{check.fe_model}", check.scene_ref(), dict(check.overrides), Path(tmp) / "fe")
            if outcome.status == OK:
                data["fe"] = fe_quantities(outcome.result_dir, edem_dir, scene)
                data["fe"]["model"] = check.fe_model
                log(f"{check.name}: FE {check.fe_model} in {time.perf_counter() - start:.1f} s")
            else:
                data["fe_unavailable"] = f"FE reference not available: the FE {check.fe_model} {outcome.status}: {outcome.message.splitlines()[0] if outcome.message else ''}"
                log(f"{check.name}: {data['fe_unavailable']}")
        elif not with_fe and (kept := _stored_fe(check, references, edem, log)) is not None:
            data["fe"], data["fe_kept_from"] = kept
            log(f"{check.name}: kept the stored FE values of {kept[1]} (--no-fe)")
        else:
            data["fe_unavailable"] = why
            log(f"{check.name}: {why}")
        if with_fe and data["fe"] is None and _stored_fe(check, references, None, lambda _text: None) is not None:
            log(f"{check.name}: dropped the stored FE values: {data['fe_unavailable']}")
    references.mkdir(parents=True, exist_ok=True)
    path = references / f"{check.name}.json"
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(json_safe(data), indent=1) + "\n", encoding="utf-8")
    os.replace(tmp, path)  # an interrupted refresh leaves the previous reference whole
    return data


def _stored_fe(check: CheckScene, references: Path, edem: dict[str, Any] | None, log=print) -> tuple[dict[str, Any], str] | None:
    """The FE values (and when they were computed) of the stored reference, if it has valid ones.

    With ``edem`` (the new baseline), InputError when they are for other time points: they
    cannot be kept then, and dropping them silently is not an option.
    """
    path = references / f"{check.name}.json"
    if not path.is_file():
        return None
    try:
        data = read_reference(check, references)
    except InputError as exc:
        log(f"{check.name}: no stored FE values can be kept: {exc}")
        return None  # nothing valid stored: nothing to keep
    if data.get("fe") is None:
        return None
    stored = data["fe"]["time_s"]
    if edem is not None and not (len(stored) == len(edem["time_s"]) and np.allclose(stored, edem["time_s"])):
        raise InputError("the stored FE values are for other time points than the scene's now, so --no-fe cannot keep them",
                         file=path, key="fe.time_s", expected=f"{edem['time_s']}: refresh with the FE reference (without --no-fe)")
    return data["fe"], str(data.get("fe_kept_from") or data.get("refreshed_at", "an earlier refresh"))


def read_reference(check: CheckScene, references: Path) -> dict[str, Any]:
    path = references / f"{check.name}.json"
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError("no stored reference", file=path, expected="the files of verification/references/ (edem check --refresh writes them)") from None
    except ValueError as exc:
        raise InputError(f"not valid JSON: {exc}", file=path) from None
    if not isinstance(data, dict) or data.get("format") != FORMAT_VERSION:
        found = data.get("format") if isinstance(data, dict) else None
        why = " (format 1 stored the raw peak, not the regularised peak that is compared now)" if found == 1 else ""
        raise InputError(f"a reference of format {found!r}{why}", file=path, key="format",
                         expected=f"format {FORMAT_VERSION}: rewrite the references with edem check --refresh")
    if "edem" not in data:
        raise InputError("no EDEM baseline", file=path, key="edem", expected="the EDEM values per time point (edem check --refresh)")
    _check_quantities(data["edem"], path, "edem")
    if data.get("fe") is not None:
        _check_quantities(data["fe"], path, "fe")
    elif not str(data.get("fe_unavailable") or "").strip():
        raise InputError('"fe" is null and the reference says nowhere why', file=path, key="fe",
                         expected='the FE values (edem check --refresh with the FE reference) or "fe_unavailable" giving the reason')
    return data


def _check_quantities(values: Any, path: Path, key: str) -> None:
    """InputError naming ``key.<quantity>`` unless every stored quantity has one finite value per time point."""

    def finite(x: Any) -> bool:
        return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)

    expected = "one finite value per time point (edem check --refresh)"
    if not isinstance(values, dict):
        raise InputError("not a table of quantities", file=path, key=key, expected=expected)
    times = values.get("time_s")
    if not isinstance(times, list) or not times or not all(finite(t) for t in times):
        raise InputError("missing, null or non-finite", file=path, key=f"{key}.time_s", expected=expected)
    for quantity in QUANTITIES:
        series = values.get(quantity)
        if not isinstance(series, list) or len(series) != len(times):
            raise InputError(f"missing, null or not {len(times)} value(s)", file=path, key=f"{key}.{quantity}", expected=expected)
        for k, value in enumerate(series):
            if quantity == "displacement_mm":
                ok = isinstance(value, list) and len(value) == 3 and all(finite(x) for x in value)
            elif quantity == "pressure_field":
                ok = (isinstance(value, dict) and finite(value.get("voxel_mm")) and isinstance(value.get("cells"), list)
                      and isinstance(value.get("pressure_mpa"), list) and len(value["cells"]) == len(value["pressure_mpa"])
                      and all(finite(p) for p in value["pressure_mpa"]))
            else:
                ok = finite(value)
            if not ok:
                raise InputError(f"time point {k}: {value!r} is not a valid value", file=path, key=f"{key}.{quantity}", expected=expected)


def check_scene(check: CheckScene, references: Path) -> list[dict[str, Any]]:
    """Rows (scene, kind, against, quantity, value, tolerance, verdict) of one scene's check: kind
    "drift", "model", or "note" (a warning the FE reference stored, in verdict)."""
    reference = read_reference(check, references)
    with tempfile.TemporaryDirectory(prefix=f"edem-check-{check.name}-") as tmp:
        edem, _, _ = _run_edem(check, Path(tmp))
    rows = []
    changes = drift(edem, reference["edem"])
    for quantity in QUANTITIES:
        value, tol = changes[quantity], EDEM_TOLERANCES[quantity]
        rows.append({"scene": check.name, "kind": "drift", "against": "EDEM baseline", "quantity": quantity, "value": value, "tolerance": tol,
                     "verdict": "same" if value <= tol else DRIFT})
    if reference.get("fe"):
        from verification.verdicts import MODEL_BAND_REL, NOT_JUDGED

        error = model_errors(edem, reference["fe"])
        for quantity in QUANTITIES:
            value = error[quantity]
            judged = quantity not in REPORTED_ONLY
            verdict = NOT_JUDGED if not judged else "within band" if abs(value) <= MODEL_BAND_REL else FLAGGED
            rows.append({"scene": check.name, "kind": "model", "against": f"FE {reference['fe'].get('model', '')}".strip(), "quantity": quantity, "value": value,
                         "tolerance": MODEL_BAND_REL if judged else None, "verdict": verdict})
        # what makes the FE not like for like (e.g. the ligaments it does not model): beside its errors
        rows += [{"scene": check.name, "kind": "note", "verdict": text} for text in reference["fe"].get("summary", {}).get("warnings", [])]
    else:
        rows.append({"scene": check.name, "kind": "model", "against": "FE", "quantity": "-", "value": None, "tolerance": None,
                     "verdict": reference.get("fe_unavailable", "FE reference not available")})
    return rows


def format_rows(rows: list[dict[str, Any]]) -> str:
    """The rows as a table: drift as |relative change| (a magnitude), model errors in %, signed
    except the field's L2 norm, with the band as +-limit."""
    head = f"{'scene':18s} {'against':14s} {'quantity':30s} {'|rel. change|' if rows and rows[0]['kind'] == 'drift' else 'signed error':>14s} {'limit':>10s}  verdict"
    lines = [head, "-" * len(head)]
    for r in rows:
        if r["value"] is None:
            value = ""
        else:
            value = f"{r['value']:.3e}" if r["kind"] == "drift" else f"{100 * r['value']:{'' if r['quantity'] in UNSIGNED else '+'}.1f} %"
        tol = "" if r["tolerance"] is None else f"{r['tolerance']:.3g}" if r["kind"] == "drift" else f"+-{100 * r['tolerance']:.0f} %"
        lines.append(f"{r['scene']:18s} {r['against']:14s} {r['quantity']:30s} {value:>14s} {tol:>10s}  {r['verdict']}")
    return "\n".join(lines)


def run_check(*, refresh: bool = False, references: str | Path | None = None, scenes: tuple[CheckScene, ...] = CHECK_SCENES, with_fe: bool = True, out=None) -> int:
    """The gate (exit status 0 / 1) or, with ``refresh``, the rewrite of the references (0)."""
    out = out or sys.stdout
    directory = Path(references) if references else REFERENCES_DIR
    if refresh:
        for check in scenes:
            refresh_reference(check, directory, with_fe=with_fe, log=lambda text: print(f"edem check --refresh: {text}", file=out))
        print(f"references written to {directory}/", file=out)
        return 0
    from verification.verdicts import MODEL_BAND_REL

    rows = [row for check in scenes for row in check_scene(check, directory)]
    drift_rows = [r for r in rows if r["kind"] == "drift"]
    model_rows = [r for r in rows if r["kind"] == "model"]
    drifted = [r for r in drift_rows if r["verdict"] == DRIFT]
    flagged = [r for r in model_rows if r["verdict"] == FLAGGED]
    print("Drift: EDEM against its stored baseline, |relative change| (the same code must give the same numbers; this is the gate, on the magnitude)", file=out)
    print(format_rows(drift_rows), file=out)
    print("", file=out)
    print(f"Model error: EDEM against the stored FE reference, signed (EDEM - FE) / |FE| (displacement: negative when EDEM's bone moves less; "
          f"field: L2 norm); reported, not a gate; flagged beyond the declared +-{MODEL_BAND_REL:.0%} model band; the raw peak is reported, "
          "the regularised peak (largest mean over 1 mm^2) judged", file=out)
    print(format_rows(model_rows), file=out)
    notes = [r for r in rows if r["kind"] == "note"]
    if notes:
        print("The FE reference's own warnings (stored with it):", file=out)
        for r in notes:
            print(f"  {r['scene']}: {r['verdict']}", file=out)
    print("", file=out)
    if drifted:
        print(f"edem check: {len(drifted)} of {len(drift_rows)} quantities drifted from the stored baseline:", file=out)
        print(format_rows(drifted), file=out)
    summary = f"{len(flagged)} of {sum(1 for r in model_rows if r['tolerance'] is not None)} model errors flagged beyond the band"
    print(f"edem check: {'FAILED: drift' if drifted else 'ok: no drift'} ({len(scenes)} scenes against {directory}); {summary}", file=out)
    return 1 if drifted else 0
