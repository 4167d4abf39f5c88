"""Campaign-level analyses (:class:`verification.campaigns.Analysis`), computed after the cases.

Each kind is a function of the analysis and the campaign's case rows (name -> row with
"metrics", "params", "status", "sides") returning a JSON-able table::

    {"name", "title", "kind", "status", "columns", "rows", "notes", "values"}

``status`` is "verified" / "failed" for judged analyses (observed orders with a minimum),
"reported" for comparisons without a verdict, "flagged" when such a comparison has rows beyond
its declared band (the thesis's figures) and "unavailable" when their cases could not run. ``values`` holds the numbers for programs (tests, other reports);
``rows`` holds display strings. A row may carry ``"flag": true`` (a large difference to look at).

* ``order``: observed convergence orders of a mesh sweep (:func:`verification.fe_analytic.observed_orders`):
  "vs-exact" from errors against a closed form, "richardson" from three values; judged when the
  check declares ``min_order`` (mean order >= it; with ``monotone``, errors must decrease too).
  Errors below ``roundoff`` on every mesh mean the discretisation is exact there: no order.
* ``thesis``: our metric of a case (times ``scale``) beside the thesis's number, with the
  relative difference, flagged beyond ``flag_rel``; rows of unavailable cases say why.
* ``sensitivity``: a metric over a two-parameter grid; relative change across each parameter's
  range (from its lowest to its highest value, at every value of the other parameter) beside the
  thesis's.
* ``table``: one row per case, one column per metric; cases that did not run say why.
* ``goal``: a target declared in advance for pairs of cases (a model and its baseline against the
  same reference): each of ``metrics`` of the model within ``strict`` up to ``strict_nu`` and
  within ``loose`` beyond, and its ``ratio_metric`` at most ``ratio`` times the baseline's. Rows
  that miss it are flagged with what they miss, and the notes say where in sentences.
* ``fe-band``: a discrete model against the FE on a base mesh and its refinements: the FE's mesh
  error beside the difference, judged against a goal only where the FE's error is below it
  (:func:`fe_band_analysis`).
* ``per-load``: a discrete model against the FE at each load of one run (its time points): both
  sides' contact areas, the signed errors, the FE's own error and a verdict against a goal where
  that error is below it; optionally the areas' growth from the smallest to the largest load
  (:func:`per_load_analysis`).
* ``pairs``: one value of two cases against each other, signed (:func:`pairs_analysis`).
* ``fe-convergence``: per FE point, each compared quantity on three meshes: values, observed
  order, Richardson extrapolation and each mesh's estimated error, with the meshes' DOFs, wall
  time and peak memory (:mod:`verification.fe_convergence`); its ``values["entries"]`` are what
  ``edem verify fe-convergence --refresh-reference`` stores. Reported.
* ``trust``: the main job's opening answer in plain sentences with figures: DEM against the FE
  on the ideal and subject-like ankles on their cartilage at each load, the default bed beside
  the independent springs (signed errors of the three card metrics, the contact area's growth
  with the load, the goal), the thesis's threshold law in one row (its area set by h_max, said
  so), then the layer over thickness and at a low load.
"""

from __future__ import annotations

import math
import traceback
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from verification.fe_analytic import observed_orders
from verification.status import ERROR, FAILED, FLAGGED, OK, REFUSED, REPORTED, UNAVAILABLE, VERIFIED



def _fmt(value: Any, digits: int = 4) -> str:
    if value is None:
        return "–"
    if isinstance(value, str):
        return value
    x = float(value)
    if math.isnan(x):
        return "nan"
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return f"{x:.{digits}g}"


def _percent(value: float | None) -> str:
    return "–" if value is None or not math.isfinite(value) else f"{100.0 * value:+.1f} %"


def _metric(row: dict[str, Any], metric: str) -> float | None:
    value = row.get("metrics", {}).get(metric)
    return None if value is None else float(value)


def _unavailable_message(row: dict[str, Any]) -> str:
    """The first line of the message of the first side that did not run (or "no value")."""
    for side in row.get("sides", []):
        if side.get("status") not in (OK, None):
            first = (side.get("message") or "").splitlines()
            return first[0] if first else side["status"]
    return "no value"


# ---------------------------------------------------------------------------------------------
# order


def order_analysis(analysis, rows: dict[str, dict[str, Any]]) -> dict[str, Any]:
    settings = analysis.settings
    roundoff = float(settings.get("roundoff", 0.0))
    out_rows, values, notes = [], [], []
    status = VERIFIED
    judged = False
    for check in settings["checks"]:
        case_rows = [rows[n] for n in check["cases"] if n in rows]
        unavailable = [r for r in case_rows if r["status"] == UNAVAILABLE]
        sizes = [float(r["params"][check["x"]]) for r in case_rows]
        errors = [_metric(r, check["metric"]) for r in case_rows]
        entry: dict[str, Any] = {"label": check["label"], "metric": check["metric"], "mode": check["mode"], "sizes": sizes, "values": errors, "orders": [], "mean_order": None,
                                 "min_order": check.get("min_order"), "verdict": REPORTED}
        if unavailable or len(case_rows) != len(check["cases"]) or any(e is None for e in errors):
            why = _unavailable_message(unavailable[0]) if unavailable else "a case has no value"
            entry["verdict"] = UNAVAILABLE
            out_rows.append({"cells": [check["label"], ", ".join(_fmt(h) for h in sizes), "–", "–", "–", _fmt(check.get("min_order")), f"unavailable: {why}"]})
            values.append(entry)
            if check.get("min_order") is not None and not unavailable:
                status = FAILED  # a judged check without its numbers: something crashed
            continue
        exact = check["mode"] == "vs-exact" and roundoff > 0 and max(abs(e) for e in errors) < roundoff
        if exact:
            entry["verdict"] = "exact"
            verdict = f"exact to round-off (every error < {roundoff:g}): no order"
        else:
            orders = observed_orders(sizes, errors, check["mode"])
            finite = [o for o in orders if math.isfinite(o)]
            entry["orders"] = orders
            entry["mean_order"] = float(np.mean(finite)) if finite else math.nan
            verdict = REPORTED
            if check.get("min_order") is not None:
                judged = True
                ok = entry["mean_order"] >= float(check["min_order"])
                if check.get("monotone"):
                    ok = ok and all(abs(b) < abs(a) for a, b in zip(errors, errors[1:]))
                verdict = "met" if ok else "fail"
                if not ok:
                    status = FAILED
            elif check["mode"] == "vs-exact" and not all(abs(b) < abs(a) for a, b in zip(errors, errors[1:])):
                verdict = "reported (not monotone)"
            entry["verdict"] = verdict
        values.append(entry)
        out_rows.append(
            {
                "cells": [
                    check["label"],
                    ", ".join(_fmt(h) for h in sizes),
                    ", ".join(_fmt(e, 3) for e in errors),
                    ", ".join(_fmt(o, 3) for o in entry["orders"]) or "–",
                    _fmt(entry["mean_order"], 3),
                    _fmt(check.get("min_order")),
                    verdict,
                ],
                "flag": verdict == "fail",
            }
        )
    if not judged and status == VERIFIED:
        status = REPORTED
    if all(v["verdict"] == UNAVAILABLE for v in values):
        status = UNAVAILABLE
    notes.append("vs-exact: log(e_i / e_i+1) / log(h_i / h_i+1) between successive meshes; richardson: log(|f1 - f2| / |f2 - f3|) / log(r).")
    return {
        "columns": ["quantity", "mesh sizes (mm)", "errors / values", "orders", "mean order", "minimum", "verdict"],
        "rows": out_rows,
        "status": status,
        "notes": notes,
        "values": {"checks": values},
    }


# ---------------------------------------------------------------------------------------------
# thesis


def thesis_analysis(analysis, rows: dict[str, dict[str, Any]]) -> dict[str, Any]:
    flag_rel = float(analysis.settings.get("flag_rel", 0.25))
    out_rows, values = [], []
    for spec in analysis.settings["rows"]:
        row = rows.get(spec["case"])
        scale = float(spec.get("scale", 1.0))
        thesis = spec.get("thesis")
        label = [spec.get("scene", ""), spec["quantity"], spec.get("method", "")]
        if row is None or row["status"] in (UNAVAILABLE, ERROR) or _metric(row, spec["metric"]) is None:
            why = "case not run" if row is None else _unavailable_message(row)
            if row is not None and any(s.get("status") == REFUSED for s in row.get("sides", [])):
                side = next(s for s in row["sides"] if s.get("status") == REFUSED)
                why = f"{side['side']} refused: {why}"
            values.append({**spec, "ours": None, "difference": None, "flag": False, "note": why})
            out_rows.append({"cells": label + ["–", _fmt(thesis), "–", why]})
            continue
        ours = _metric(row, spec["metric"]) * scale
        difference = None if thesis in (None, 0) else (ours - float(thesis)) / float(thesis)
        flag = difference is not None and abs(difference) > flag_rel
        values.append({**spec, "ours": ours, "difference": difference, "flag": flag})
        note = f"large difference (> {100 * flag_rel:.0f} %)" if flag else ""
        out_rows.append({"cells": label + [_fmt(ours), _fmt(thesis), _percent(difference), note], "flag": flag})
    available = [v for v in values if v["ours"] is not None]
    return {
        "columns": ["scene", "quantity", "method", "ours", "thesis", "difference", "note"],
        "rows": out_rows,
        "status": (FLAGGED if any(v["flag"] for v in values) else REPORTED) if available else UNAVAILABLE,
        "notes": [f"Reported, no verdict: the thesis's figures come from its own meshes and loads (docs/references.md#the-thesiss-figures); differences beyond {100 * flag_rel:.0f} % are flagged."],
        "values": {"rows": values},
    }


# ---------------------------------------------------------------------------------------------
# sensitivity


def grid_of(rows: dict[str, dict[str, Any]], names: tuple[str, ...], x: str, y: str, metric: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(xs, ys, Z[i, j] = metric at xs[i], ys[j]) of the cases ``names`` (NaN where missing)."""
    points = [(float(rows[n]["params"][x]), float(rows[n]["params"][y]), _metric(rows[n], metric)) for n in names if n in rows]
    xs = np.array(sorted({p[0] for p in points}))
    ys = np.array(sorted({p[1] for p in points}))
    z = np.full((len(xs), len(ys)), np.nan)
    for px, py, v in points:
        if v is not None:
            z[np.searchsorted(xs, px), np.searchsorted(ys, py)] = v
    return xs, ys, z


def sensitivity_analysis(analysis, rows: dict[str, dict[str, Any]]) -> dict[str, Any]:
    s = analysis.settings
    flag_rel = float(s.get("flag_rel", 0.25))
    xs, ys, z = grid_of(rows, analysis.cases, s["x"], s["y"], s["metric"])
    if not np.isfinite(z).any():
        return {"columns": [], "rows": [], "status": UNAVAILABLE, "notes": ["no case has a value"], "values": {}}
    # relative change from the lowest to the highest value of one parameter, at each value of the other

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN rows of a partly failed grid stay NaN
        along_x = (z[-1, :] - z[0, :]) / z[0, :]
        along_y = (z[:, -1] - z[:, 0]) / z[:, 0]
        spread_y = (np.nanmax(z, axis=1) - np.nanmin(z, axis=1)) / np.nanmin(z, axis=1)
    out_rows, values = [], {}
    floor = float(s.get("flag_abs", 0.02))  # differences of a few points on a few % are not "large"

    def summary_of(changes: np.ndarray) -> dict[str, float]:
        finite = changes[np.isfinite(changes)]
        if not finite.size:
            return {"mean": math.nan, "min": math.nan, "max": math.nan}
        return {"mean": float(finite.mean()), "min": float(finite.min()), "max": float(finite.max())}

    def flagged(ours: float, thesis: float | None) -> bool:
        return thesis is not None and math.isfinite(ours) and abs(ours - thesis) > max(flag_rel * abs(thesis), floor)

    rows_spec = (
        ("x_change", f"change of the peak, {s['x']} {xs[0]:g} -> {xs[-1]:g}", along_x, s.get("thesis_x_change"), s["y"]),
        ("y_spread", f"spread (max - min) / min of the peak over {s['y']} {ys[0]:g} .. {ys[-1]:g}", spread_y, s.get("thesis_y_change"), s["x"]),
        ("y_change", f"change of the peak, {s['y']} {ys[0]:g} -> {ys[-1]:g}", along_y, None, s["x"]),
    )
    for key, label, changes, thesis, other in rows_spec:
        entry = summary_of(changes)
        flag = flagged(entry["mean"], thesis)
        values[key] = {**entry, "thesis": thesis, "flag": bool(flag), "per_other_value": changes.tolist()}
        out_rows.append(
            {
                "cells": [label, f"{_percent(entry['mean'])} mean (from {_percent(entry['min'])} to {_percent(entry['max'])} over {other})", _percent(thesis) if thesis is not None else "–", "large difference" if flag else ""],
                "flag": flag,
            }
        )
    values["range"] = {"min": float(np.nanmin(z)), "max": float(np.nanmax(z)), "missing": int(np.isnan(z).sum()), "grid": [len(xs), len(ys)]}
    out_rows.append({"cells": [f"{s['metric']} over the grid", f"{np.nanmin(z):.4g} .. {np.nanmax(z):.4g}" + (f" ({values['range']['missing']} missing)" if values["range"]["missing"] else ""), "–", ""]})
    return {
        "columns": ["quantity", "ours", "thesis", "note"],
        "rows": out_rows,
        "status": REPORTED,
        "notes": [
            "Reported, no verdict (docs/references.md#the-thesiss-figures: the thesis's fig. 4.3.10 from its own mesh and stance). A change is (value at the highest - value at the lowest) / value at the "
            f"lowest, at each value of the other parameter; flagged when it differs from the thesis's by more than {100 * flag_rel:.0f} % of it (and {100 * floor:.0f} points)."
        ],
        "values": values,
    }


# ---------------------------------------------------------------------------------------------
# table


def table_analysis(analysis, rows: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """One row per case, one column per metric (``settings["columns"]``: header, metric, scale;
    or header and ``fe_error``: the FE reference's own estimated error of that comparison metric,
    verification.fe_convergence, "unknown" when its run is not in the study); cases that did not
    run give their reason instead of numbers."""
    from verification.fe_convergence import UNKNOWN_FE_ERROR, fe_relative_error, load_reference

    all_columns = analysis.settings["columns"]
    columns = [c for c in all_columns if "metric" in c]
    fe_columns = [c for c in all_columns if "fe_error" in c]
    reference = load_reference() if fe_columns else None
    out_rows, values = [], []
    for name in analysis.cases:
        row = rows.get(name)
        numbers = [None if row is None or _metric(row, c["metric"]) is None else _metric(row, c["metric"]) * float(c.get("scale", 1.0)) for c in columns]
        note = ""
        if row is None:
            note = "case not run"
        elif any(s.get("status") != OK for s in row.get("sides", [])):
            side = next(s for s in row["sides"] if s.get("status") != OK)
            note = f"{side['side']} {side['status']}: {_unavailable_message(row)}"
        fe_errors = fe_relative_error(row, reference) if fe_columns and row is not None else None
        fe_cells = [UNKNOWN_FE_ERROR if fe_errors is None or c["fe_error"] not in fe_errors else _size_pct(fe_errors[c["fe_error"]]) for c in fe_columns]
        values.append({"case": name, "values": {c["metric"]: v for c, v in zip(columns, numbers)}, "note": note,
                       **({"fe_error": fe_errors} if fe_columns else {})})
        out_rows.append({"cells": [name] + [_fmt(v) for v in numbers] + fe_cells + [note]})
    available = any(v is not None for entry in values for v in entry["values"].values())
    return {
        "columns": ["case"] + [c["header"] for c in columns] + [c["header"] for c in fe_columns] + ["note"],
        "rows": out_rows,
        "status": REPORTED if available else UNAVAILABLE,
        "notes": [],
        "values": {"rows": values},
    }


def pareto_front(points: list[tuple[float, float]]) -> list[bool]:
    """For each (time, error): True when no other point is at least as good in both and better in one."""
    out = []
    for i, (t, e) in enumerate(points):
        dominated = any(t2 <= t and e2 <= e and (t2 < t or e2 < e) for j, (t2, e2) in enumerate(points) if j != i)
        out.append(not dominated)
    return out


def pareto_analysis(analysis, rows: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Error (``settings["metric"]``) against side a's wall time; the non-dominated cases flagged
    "front", one front per truth (side b). A case's family is its name up to the last '-' (dem, fe-p1, edem)."""
    metric = analysis.settings["metric"]
    entries = []
    for name in analysis.cases:
        row = rows.get(name)
        if row is None or row["status"] in (UNAVAILABLE, ERROR) or not row.get("sides"):
            continue
        error = row["metrics"].get(metric)
        time_s = row["sides"][0].get("wall_time_s")
        if error is None or time_s is None:
            continue
        error, time_s = float(error), float(time_s)
        if math.isfinite(error) and math.isfinite(time_s):
            entries.append({"case": name, "family": name.rsplit("-", 1)[0], "time_s": time_s, "error": error, "truth_time_s": float(row["sides"][1]["wall_time_s"]) if len(row["sides"]) > 1 else None,
                            "truth": row["sides"][1].get("side", "") if len(row["sides"]) > 1 else ""})
    if not entries:
        return {"columns": [], "rows": [], "status": UNAVAILABLE, "notes": ["no case has a value"], "values": {}}
    # a front per truth (errors against different truths are not comparable)
    for truth in dict.fromkeys(e["truth"] for e in entries):
        group = [e for e in entries if e["truth"] == truth]
        for entry, on in zip(group, pareto_front([(e["time_s"], e["error"]) for e in group])):
            entry["front"] = on
    entries.sort(key=lambda e: e["time_s"])
    entries.sort(key=lambda e: (e["truth"], e["time_s"]))
    out_rows = [{"cells": [e["case"], e["family"], e["truth"], _fmt(e["time_s"], 3), _fmt(e["error"], 3), "front" if e["front"] else ""], "flag": False} for e in entries]
    truths = {}
    for e in entries:
        if e["truth_time_s"] is not None:
            truths.setdefault(e["family"], []).append(e["truth_time_s"])
    notes = [analysis.settings.get("truth", "")] + [f"{fam}: its truth took {min(ts):.3g} .. {max(ts):.3g} s per run" for fam, ts in truths.items()]
    notes.append("Wall time of side a as run by the campaign (2 jobs sharing 2 cores: contention included); front = no other point against the same truth is both faster and more accurate (one front per truth: errors against different truths do not compare).")
    return {
        "columns": ["case", "family", "against", "wall time a (s)", metric, "Pareto"],
        "rows": out_rows,
        "status": REPORTED,
        "notes": [n for n in notes if n],
        "values": {"points": entries, "front": [e["case"] for e in entries if e["front"]]},
    }


# ---------------------------------------------------------------------------------------------
# goal


def goal_misses(nu: float, errors: dict[str, float | None], ratio: float | None, settings: dict[str, Any]) -> list[str]:
    """What a point misses of the goal (``settings`` of a goal analysis): "displacement 12 % > 10 %", ...;
    a missing value misses too."""
    limit = float(settings["strict"]) if nu <= float(settings["strict_nu"]) else float(settings["loose"])
    misses = []
    for metric, value in errors.items():
        label = metric.replace("_rel_error", "").replace("_", " ")
        if value is None or not math.isfinite(value):
            misses.append(f"{label} missing")
        elif abs(value) > limit:
            misses.append(f"{label} {100 * value:+.1f} % outside ±{100 * limit:.0f} %")
    if ratio is None or not math.isfinite(ratio):
        misses.append("L2 ratio missing")
    elif ratio > float(settings["ratio"]):
        misses.append(f"L2 {ratio:.2f} x the baseline's > {float(settings['ratio']):g}")
    return misses


def unjudged_by_fe_error(errors: dict[str, float | None], fe_errors: dict[str, float] | None, limit: float) -> dict[str, str]:
    """The metrics of ``errors`` a goal of ``limit`` cannot judge against this FE reference, with
    why: its own estimated error (``fe_errors``, verification.fe_convergence.fe_relative_error)
    unknown, or at least the goal ("FE error too large to judge": a band no wider than the
    reference's own error judges nothing)."""
    out = {}
    for metric in errors:
        label = metric.replace("_rel_error", "").replace("_", " ")
        fe = None if fe_errors is None else fe_errors.get(metric)
        if fe is None:
            out[metric] = f"{label}: FE error unknown"
        elif not fe < limit:
            out[metric] = f"{label}: FE error too large to judge ({100 * fe:.1f} % >= {100 * limit:.0f} %)"
    return out


def goal_analysis(analysis, rows: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """``settings``: pairs ((model case, baseline case), ...), metrics, strict, strict_nu, loose,
    ratio_metric, ratio, note (optional), fe_error (optional: judge each metric only where the
    model case's FE reference has a known own error below the goal, :func:`unjudged_by_fe_error`).
    The sentences group the points by the model case's name up to its last '-' (e.g.
    layer-coupled-F333-t2)."""
    s = analysis.settings
    metrics, ratio_metric = tuple(s["metrics"]), s["ratio_metric"]
    reference = None
    if s.get("fe_error"):
        from verification.fe_convergence import fe_relative_error, load_reference

        reference = load_reference()
    out_rows, values, missed, met, unjudged_groups = [], [], {}, {}, {}
    for model_name, base_name in s["pairs"]:
        model, base = rows.get(model_name), rows.get(base_name)
        if model is None or not model.get("metrics"):
            why = "case not run" if model is None else _unavailable_message(model)
            out_rows.append({"cells": [model_name, "–"] + ["–"] * (len(metrics) + 3) + [f"not compared: {why}"], "flag": True})
            continue
        nu = float(model["params"].get("poissons_ratio", math.nan))
        errors = {m: _metric(model, m) for m in metrics}
        mine, theirs = _metric(model, ratio_metric), None if base is None else _metric(base, ratio_metric)
        ratio = None if mine is None or not theirs else mine / theirs
        unjudged = {} if reference is None else unjudged_by_fe_error(
            errors, fe_relative_error(model, reference), float(s["strict"]) if nu <= float(s["strict_nu"]) else float(s["loose"]))
        misses = goal_misses(nu, {m: e for m, e in errors.items() if m not in unjudged}, ratio, s)
        group = model_name.rsplit("-", 1)[0]
        if misses or not unjudged:  # met only where every metric was judged
            (missed if misses else met).setdefault(group, []).append((nu, misses))
        if unjudged:
            unjudged_groups.setdefault(group, []).append((nu, list(unjudged.values())))
        values.append({"case": model_name, "baseline": base_name, "poissons_ratio": nu, "errors": errors, ratio_metric: mine,
                       f"baseline_{ratio_metric}": theirs, "ratio": ratio, "misses": misses, "not_judged": unjudged})
        verdict = "met" if not misses else "not met: " + "; ".join(misses)
        if unjudged:
            verdict = ("not judged: " if len(unjudged) == len(metrics) else verdict + "; not judged: ") + "; ".join(unjudged.values())
        out_rows.append({"cells": [model_name, _fmt(nu)] + [_pct(e) for e in errors.values()]
                         + [_pct(mine), _pct(theirs), _fmt(ratio, 3), verdict], "flag": bool(misses)})
    notes = []
    for group in dict.fromkeys([*missed, *met, *unjudged_groups]):
        bad, good = missed.get(group, []), met.get(group, [])
        text = f"{group}: goal met at nu " + (", ".join(f"{nu:g}" for nu, _m in good) if good else "none")
        if bad:
            text += "; not met at " + "; ".join(f"nu {nu:g} ({', '.join(m)})" for nu, m in bad)
        if group in unjudged_groups:
            text += "; not judged at " + "; ".join(f"nu {nu:g} ({', '.join(m)})" for nu, m in unjudged_groups[group])
        notes.append(text + ".")
    columns = ["case", "nu"] + [m.replace("_rel_error", " err").replace("_", " ") for m in metrics] + [f"{ratio_metric.replace('_rel_error', '')} (model)", "(baseline)", "ratio", "goal"]
    return {
        "columns": columns,
        "rows": out_rows,
        "status": UNAVAILABLE if not values else (FLAGGED if any(r["flag"] for r in out_rows) else REPORTED),
        "notes": notes + [s.get("note", "")] if s.get("note") else notes,
        "values": {"rows": values, "met": sum(1 for v in values if not v["misses"] and not v.get("not_judged")), "points": len(values)},
    }


# ---------------------------------------------------------------------------------------------
# trust


def _signed(row: dict[str, Any], quantity: str) -> tuple[float | None, float | None, float | None]:
    """(discrete value, FE value, signed relative difference) of ``quantity``
    (regularised_peak_pressure_mpa, mean_contact_area_mm2, displacement_norm_mm...) at the FE's time points."""
    a, b = _metric(row, f"a_at_b_{quantity}"), _metric(row, f"b_{quantity}")
    if a is None or b is None or b == 0:
        return a, b, None
    return a, b, (a - b) / b


def _pct(x: float | None) -> str:
    """A signed relative difference in whole percent; one that rounds to nothing is "0 %" (not "-0 %")."""
    if x is None or not math.isfinite(x):
        return "–"
    return "0 %" if round(100.0 * x) == 0 else f"{100.0 * x:+.0f} %"


def _load_points(row: dict[str, Any]) -> list[dict[str, Any]]:
    """Per load of a DEM-vs-FE case (its time points, :func:`per_time_comparison`; else the
    headline values of its metrics at ``params["load_n"]``): the load and, for displacement
    (the norm of the bone's motion), regularised peak and contact area, (DEM, FE, signed relative
    difference; for the displacement at the time points the judged vector difference, signed by
    which bone moves less), and the pressure field's L2 error."""
    per_time = per_time_comparison(row)
    if per_time is None:
        return [{"load_n": (row.get("params") or {}).get("load_n"), "l2": _metric(row, "pressure_l2_rel_error"),
                 **{key: _signed(row, quantity) for key, quantity in (("disp", "displacement_norm_mm"), ("peak", "regularised_peak_pressure_mpa"),
                                                                       ("area", "mean_contact_area_mm2"))}}]

    def signed(a: float, b: float) -> tuple[float, float, float | None]:
        return a, b, (a - b) / b if b else None

    # the displacement's difference is the judged one: |u_a - u_b| / |u_b|, negative where the bone moves less
    return [{"load_n": e["load_n"], "l2": e.get("pressure_l2_rel_error"),
             "disp": (float(np.linalg.norm(e["displacement_a_mm"])), float(np.linalg.norm(e["displacement_b_mm"])), e["displacement_rel_error"]),
             "peak": signed(e["regularised_peak_pressure_a_mpa"], e["regularised_peak_pressure_b_mpa"]),
             "area": signed(e["contact_area_a_mm2"], e["contact_area_b_mm2"])} for e in per_time]


def _values_text(points: list[dict[str, Any]], key: str, digits: int, unit: str) -> str:
    """"a1 / a2 / a3 unit against b1 / b2 / b3 unit (e1, e2, e3)" over the loads."""
    return (" / ".join(_fmt(p[key][0], digits) for p in points) + f" {unit} against " + " / ".join(_fmt(p[key][1], digits) for p in points)
            + f" {unit} (" + ", ".join(_pct(p[key][2]) for p in points) + ")")


def _why_missed(row: dict[str, Any], metric: str, error: float | None, reference: dict[str, Any]) -> str:
    """Why a card metric misses the goal, in a few words: by construction, the FE's own error
    (at least the miss, or unknown), or beyond that error (a model error of the bed or the law)."""
    if (row.get("verdicts") or {}).get(metric, {}).get("kind") == "by-construction":
        return ": by construction"
    from verification.fe_convergence import fe_relative_error

    fe = (fe_relative_error(row, reference) or {}).get(metric)
    if fe is None:
        return ": FE error unknown"
    if error is not None and fe >= abs(error):
        return f": within the FE's own error {100 * fe:.1f} %"
    return f": beyond the FE's own error {100 * fe:.1f} %"


def trust_analysis(analysis, rows: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Plain sentences with figures: can the default bed be trusted for an ankle, and where not.

    ``settings``: ankles ({ankle: {bed: cases over Poisson's ratio}}, the default bed first; each
    case against the FE at several loads, its time points), threshold (the thesis's threshold law's
    one case, its area set by h_max), layer_cases (gap law over thickness), layer_base, low_load,
    band (the declared model band), goal (the relative error the card metrics aim at at every
    load), area_growth (the contact area at the largest load over the smallest's, at least),
    figures, fe_note.
    """
    s = analysis.settings
    band, goal, growth = float(s["band"]), float(s["goal"]), float(s["area_growth"])
    ok = {n: rows[n] for n in analysis.cases if n in rows and rows[n]["status"] not in ("unavailable", "error") and rows[n].get("metrics")}
    ankles: dict[str, dict[str, list[str]]] = s["ankles"]
    first_ankle = next(iter(ankles))
    default_bed = next(iter(ankles[first_ankle]))
    base_name = ankles[first_ankle][default_bed][0]
    base = ok.get(base_name)
    if base is None:
        why = _unavailable_message(rows[base_name]) if base_name in rows else "case not run"
        return {"columns": [], "rows": [], "status": UNAVAILABLE, "notes": [],
                "values": {"sentences": [f"Not answered on this installation: the comparison with the FE reference did not run ({why}). Install the `fe` extra and rerun."]}}
    quantities = (("disp", "displacement", "displacement_rel_error"), ("peak", "regularised peak pressure", "regularised_peak_pressure_rel_error"),
                  ("area", "contact area", "contact_area_rel_error"))
    from verification.fe_convergence import fe_error_text, fe_relative_error, load_reference

    reference = load_reference()
    points = _load_points(base)
    loads = " / ".join(_fmt(p["load_n"], 4) for p in points)
    nu = base["params"].get("poissons_ratio")
    sentences = [
        f"The default bed, the {default_bed}, on the {first_ankle} standing on its cartilage (Poisson's ratio {_fmt(nu, 3)}, no ligaments) against the FE of "
        f"both cartilage layers, at {loads} N: the talus moves {_values_text(points, 'disp', 3, 'mm')}, the regularised peak pressure (the largest mean over "
        f"1 mm²) is {_values_text(points, 'peak', 3, 'MPa')}, the contact area {_values_text(points, 'area', 4, 'mm²')}; verdict: {base['status']} "
        f"(verified needs every judged metric at every load inside the declared ±{100 * band:.0f} % band, against an FE whose own error is known to be smaller)."
    ]
    missed, areas, unjudged, fe_texts = [], [], [], []
    for ankle, beds in ankles.items():
        for bed, names in beds.items():
            for name in names:
                row = ok.get(name)
                if row is None:
                    continue
                pts = _load_points(row)
                at = f"nu {_fmt(row['params'].get('poissons_ratio'), 3)}, at {' / '.join(_fmt(p['load_n'], 4) for p in pts)} N"
                sentences.append(f"{ankle[0].upper() + ankle[1:]}, {bed}, against the FE ({at}): "
                                 + "; ".join(f"{what} " + ", ".join(_pct(p[key][2]) for p in pts) for key, what, _m in quantities) + ".")
                if bed == default_bed:
                    fe = fe_relative_error(row, reference) or {}
                    where = f"the {ankle}" + (f" at nu {_fmt(row['params'].get('poissons_ratio'), 3)}" if len(names) > 1 else "")
                    fe_texts.append(f"{where}: " + ", ".join(f"{what} {_size_pct(fe[metric]) if metric in fe else 'unknown'}" for _k, what, metric in quantities))
                    for key, what, metric in quantities:
                        judged = fe.get(metric, math.inf) < goal  # a goal no wider than the FE's own error judges nothing
                        if not judged:
                            unjudged.append(f"{what} on {where}")
                        out = [p for p in pts if p[key][2] is None or abs(p[key][2]) > goal]
                        if out:
                            missed.append((f"{what} on {where} at " + ", ".join(f"{_fmt(p['load_n'], 4)} N" for p in out) + " ("
                                           + ", ".join(_pct(p[key][2]) + _why_missed(row, metric, p[key][2], reference) for p in out) + ")", judged))
                if len(pts) > 1:
                    lo, hi = min(pts, key=lambda p: p["load_n"]), max(pts, key=lambda p: p["load_n"])
                    ratios = [hi["area"][k] / lo["area"][k] if lo["area"][k] else math.inf for k in (0, 1)]
                    areas.append(f"the {ankle} with the {bed} {_fmt(lo['area'][0], 3)} -> {_fmt(hi['area'][0], 3)} mm² ({ratios[0]:.2f}x; the FE "
                                 f"{_fmt(lo['area'][1], 3)} -> {_fmt(hi['area'][1], 3)} mm², {ratios[1]:.2f}x)"
                                 + ("" if min(ratios) >= growth else f", short of {growth:g}x"))
    if areas:
        sentences.append("The contact area grows with the load, an outcome of the anatomy (the two layers, the bones' incongruity), not of a window: "
                         + "; ".join(areas) + f". The goal: at least {growth:g}x from the smallest load to the largest, DEM and FE.")
    verdict = "missed" if any(judged for _text, judged in missed) else "not judged" if unjudged else "met"
    sentences.append(
        f"Goal (every card metric of the default bed within {100 * goal:.0f} % of the FE at every load, judged where the FE's own estimated error is below "
        f"it): {verdict}" + (" on every ankle compared" if verdict == "met" else "")
        + (f"; outside it: {'; '.join(text for text, _judged in missed)}" if missed else "")
        + (f"; the FE's own error unknown or not below the goal for {', '.join(unjudged)}" if unjudged else "")
        + ". The FE's own estimated error at this job's level (fe-convergence, the worst over its loads): " + "; ".join(fe_texts)
        + (". Each miss says why: the FE's own error at least as large as the miss, that error unknown, or beyond it: a model error of the bed "
           "that the reference can see." if missed else "."))
    threshold = ok.get(s["threshold"])
    if threshold is not None:
        tp = _load_points(threshold)[-1]
        sentences.append(
            f"The thesis's threshold law, one row of its own ({s['threshold']}: the thesis's ideal ankle without cartilage layers, independent springs, "
            f"against the FE slab at {_fmt(tp['load_n'], 4)} N): displacement {_pct(tp['disp'][2])}, regularised peak pressure {_pct(tp['peak'][2])}, contact "
            f"area {_fmt(tp['area'][0], 4)} against {_fmt(tp['area'][1], 4)} mm² ({_pct(tp['area'][2])}); verdict {threshold['status']}. That area is set by "
            "h_max, not by the mechanics: the law puts every spring within h_max of the other bone in contact, at any load and nu, whatever the bed.")
    layers = [(float(ok[n]["params"].get("thickness_mm")), _signed(ok[n], "regularised_peak_pressure_mpa")[2], _signed(ok[n], "mean_contact_area_mm2")[2]) for n in s["layer_cases"] if n in ok]
    if layers:
        sentences.append(
            "Cartilage thickness (a cylinder with a bonded layer, independent springs with the gap law against the FE layer, 333 N): regularised peak-pressure error "
            + ", ".join(f"{_pct(e)} at {t:g} mm" for t, e, _a in layers) + "; contact-area error " + ", ".join(f"{_pct(a)}" for _t, _e, a in layers) + "."
        )
    low, layer_base = ok.get(s["low_load"]), ok.get(s["layer_base"])
    if low is not None and layer_base is not None:
        sentences.append(
            f"Low loads: at {_fmt(low['params'].get('load_n'))} N the layer's regularised peak-pressure error is {_pct(_signed(low, 'regularised_peak_pressure_mpa')[2])} against "
            f"{_pct(_signed(layer_base, 'regularised_peak_pressure_mpa')[2])} at 333 N: a small patch is mostly rim."
        )
    table = []
    for name in analysis.cases:
        row = rows.get(name)
        if row is None:
            continue
        fe_error = fe_error_text(fe_relative_error(row, reference))
        for p in _load_points(row) if name in ok else [{"load_n": (row.get("params") or {}).get("load_n"), "l2": None, "disp": (None,) * 3, "peak": (None,) * 3, "area": (None,) * 3}]:
            u, pk, a = p["disp"], p["peak"], p["area"]
            table.append({"cells": [name, _fmt(p["load_n"], 4), row["status"], _fmt(u[0], 3), _fmt(u[1], 3), _pct(u[2]), _fmt(pk[0], 3), _fmt(pk[1], 3), _pct(pk[2]),
                                    _fmt(a[0], 4), _fmt(a[1], 4), _pct(a[2]), "–" if p["l2"] is None else f"{100 * p['l2']:.0f} %", fe_error],
                          "flag": row["status"] == "flagged"})
    return {
        "columns": ["case", "load (N)", "verdict", "DEM |u| (mm)", "FE |u| (mm)", "displacement diff", "DEM regularised peak (MPa)", "FE regularised peak (MPa)", "peak diff",
                    "DEM area (mm²)", "FE area (mm²)", "area diff", "pressure L2", "FE's own error (regularised peak / area / |u| / L2)"],
        "rows": table,
        "status": FLAGGED if any(r["flag"] for r in table) else REPORTED,
        "notes": [s.get("fe_note", "")] if s.get("fe_note") else [],
        "values": {"sentences": sentences, "figures": list(s.get("figures", []))},
    }


def fe_band_analysis(analysis, rows: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """A discrete model against the FE on several meshes, judged only where the FE is converged
    enough to judge (docs/campaigns.md#real-knee-dem-against-the-fe-on-a-real-knee).

    ``settings``: ``points`` ((label, (case on the base FE mesh, case refined in one direction,
    case refined in another, ...)), ...), ``quantities`` ((name, discrete metric, FE metric), ...)
    and ``goal`` (relative). Each refinement halves the elements along one direction (through the
    thickness, in the plane), so their discretisation errors add: the FE reference is
    f = f_0 + sum_k (f_k - f_0) and its error is estimated by sum_k |f_k - f_0| / |f| (each
    refinement's change bounds the error it removed for a first-order quantity and overestimates
    it for a faster one; the extrapolation's own remainder is taken to be below that sum). With one
    refinement, f is the finer mesh's value and the error its change. Per point and quantity: the
    discrete value, the FE values, the FE error, the discrete model's relative difference to f, and
    the verdict: "within" / "outside" the goal, or "not judged" when the FE's error is not below the
    goal (a band narrower than the reference's error judges nothing). Outside rows are flagged;
    no verdict fails the campaign (status "reported" / "flagged").
    """
    settings = analysis.settings
    goal = float(settings["goal"])
    out_rows, values, notes = [], [], []
    flagged = available = False
    for label, cases in settings["points"]:
        case_rows = [rows.get(name) for name in cases]
        for quantity, a_metric, b_metric in settings["quantities"]:
            fe = [None if r is None else _metric(r, b_metric) for r in case_rows]
            discrete = None if case_rows[0] is None else _metric(case_rows[0], a_metric)
            if discrete is None or any(v is None for v in fe):
                missing = next((name for name, r in zip(cases, case_rows) if r is None or r.get("status") == UNAVAILABLE or _metric(r, b_metric) is None), cases[0])
                why = "case not run" if rows.get(missing) is None else _unavailable_message(rows[missing])
                out_rows.append({"cells": [label, quantity, "–", "–", "–", "–", "–", f"unavailable ({missing}): {why}"]})
                values.append({"point": label, "quantity": quantity, "verdict": UNAVAILABLE})
                continue
            available = True
            base = float(fe[0])
            reference = base + sum(float(v) - base for v in fe[1:])
            fe_error = sum(abs(float(v) - base) for v in fe[1:]) / abs(reference) if reference and len(fe) > 1 else math.inf
            difference = (float(discrete) - reference) / abs(reference) if reference else math.inf
            if not fe_error < goal:
                verdict = f"not judged: FE error {100 * fe_error:.1f} % >= goal {100 * goal:.0f} %"
            elif abs(difference) <= goal:
                verdict = "within"
            else:
                verdict = "outside"
            outside = verdict == "outside"
            flagged |= outside
            values.append({"point": label, "quantity": quantity, "discrete": float(discrete), "fe": [float(v) for v in fe],
                           "fe_reference": reference, "fe_error": fe_error, "difference": difference, "verdict": verdict})
            out_rows.append({"cells": [label, quantity, _fmt(discrete), ", ".join(_fmt(v) for v in fe), _fmt(reference),
                                       f"{100 * fe_error:.1f} %", f"{100 * difference:+.1f} %", verdict], "flag": outside})
    notes.append(f"goal: the discrete value within {100 * goal:.0f} % of the FE reference f = f_0 + sum_k (f_k - f_0) (each refinement "
                 "halves the elements in one direction); its error sum_k |f_k - f_0| / |f|; a point is judged only where that error is "
                 "below the goal")
    return {
        "columns": ["point", "quantity", "discrete", "FE (base, refined...)", "FE reference", "FE error", "discrete - FE", "verdict"],
        "rows": out_rows,
        "status": (FLAGGED if flagged else REPORTED) if available else UNAVAILABLE,
        "notes": notes,
        "values": {"rows": values},
    }


def per_time_comparison(row: dict[str, Any]) -> list[dict[str, Any]] | None:
    """The comparison of each time point of a case (verification.metrics.compare_result_dirs
    ``per_time``), read from its metrics.json; None when the case has none."""
    import json

    if not row.get("out_dir") or not row.get("case_dir"):
        return None
    try:
        record = json.loads((Path(row["out_dir"]) / row["case_dir"] / "metrics.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return ((record.get("comparison") or {}).get("per_time")) or None


def per_load_analysis(analysis, rows: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """A discrete model against the FE at each load of one run (its time points), judged against
    a goal where the FE's own error is below it.

    ``settings``: ``quantities`` ((name, comparison metric), ...) judged against ``goal`` (relative;
    None: reported only) where the FE reference's estimated error of that metric
    (:func:`verification.fe_convergence.fe_relative_error`) is below the goal ("not judged" where
    it is not, "FE error unknown" without one); ``reported`` ((name, metric), ...) shown beside
    them; ``area_growth``: the contact area at the largest load must be at least this many times
    the area at the smallest, for each side (None: not checked). Rows: one per case and load with
    both sides' contact areas, the signed errors, the FE's own errors and the verdict; rows
    outside the goal or short of the growth are flagged (reported, never failed)."""
    from verification.fe_convergence import fe_relative_error, load_reference

    settings = analysis.settings
    goal = settings.get("goal")
    growth = settings.get("area_growth")
    quantities = [tuple(q) for q in settings["quantities"]]
    reported = [tuple(q) for q in settings.get("reported", ())]
    reference = load_reference()
    out_rows, values, notes = [], [], []
    flagged = available = False
    for name in analysis.cases:
        row = rows.get(name)
        per_time = None if row is None else per_time_comparison(row)
        if per_time is None:
            why = "case not run" if row is None else _unavailable_message(row)
            out_rows.append({"cells": [name, "–", "–", "–"] + ["–"] * (len(quantities) + len(reported)) + ["–", f"unavailable: {why}"]})
            values.append({"case": name, "verdict": UNAVAILABLE})
            continue
        available = True
        fe_errors = fe_relative_error(row, reference)
        fe_text = " / ".join("unknown" if fe_errors is None or m not in fe_errors else _size_pct(fe_errors[m]) for _, m in quantities)
        for entry in per_time:
            errors = {metric: entry.get(metric) for _, metric in quantities + reported}
            verdict = "reported"
            if goal is not None:
                outside = [q for q, m in quantities if errors[m] is not None and abs(errors[m]) > goal]
                unjudged = [q for q, m in quantities if fe_errors is None or m not in fe_errors or not fe_errors[m] < goal]
                judged_out = [q for q in outside if q not in unjudged]
                if judged_out:
                    verdict = "outside: " + ", ".join(judged_out)
                elif unjudged:
                    verdict = ("not judged (FE error unknown or >= goal): " + ", ".join(unjudged)
                               + (f"; outside: {', '.join(outside)}" if outside else ""))
                else:
                    verdict = "within"
            flag = verdict.startswith("outside")
            flagged |= flag
            values.append({"case": name, "load_n": entry["load_n"], "area_a_mm2": entry["contact_area_a_mm2"], "area_b_mm2": entry["contact_area_b_mm2"],
                           "errors": errors, "fe_error": fe_errors, "verdict": verdict})
            out_rows.append({"cells": [name, _fmt(entry["load_n"]), _fmt(entry["contact_area_a_mm2"]), _fmt(entry["contact_area_b_mm2"])]
                             + [_percent(errors[m]) for _, m in quantities + reported] + [fe_text, verdict], "flag": flag})
        if growth is not None and len(per_time) > 1:
            first, last = min(per_time, key=lambda e: e["load_n"]), max(per_time, key=lambda e: e["load_n"])
            ratios = [last[f"contact_area_{side}_mm2"] / first[f"contact_area_{side}_mm2"] if first[f"contact_area_{side}_mm2"] > 0 else math.inf
                      for side in "ab"]
            short = [side for side, r in zip(("DEM", "FE"), ratios) if not r >= growth]
            flagged |= bool(short)
            notes.append(f"{name}: contact area at {_fmt(last['load_n'])} N / at {_fmt(first['load_n'])} N = {ratios[0]:.2f} (a), {ratios[1]:.2f} (b, the FE): "
                         + (f"short of {growth:g}x for " + " and ".join(short) if short else f"at least {growth:g}x for both"))
    if goal is not None:
        notes.append(f"goal: {', '.join(q for q, _ in quantities)} within {100 * goal:.0f} % of the FE at every load, judged where the FE's own estimated error "
                     "(fe-convergence, the worst over its time points) is below the goal")
    return {
        "columns": ["case", "load (N)", "area a (mm^2)", "area b, FE (mm^2)"] + [f"{q} err" for q, _ in quantities + reported]
        + [f"FE's own err ({' / '.join(q for q, _ in quantities)})", "verdict"],
        "rows": out_rows,
        "status": (FLAGGED if flagged else REPORTED) if available else UNAVAILABLE,
        "notes": notes,
        "values": {"rows": values},
    }


def pairs_analysis(analysis, rows: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """One value of two cases against each other: ``settings["pairs"]`` ((label, case a, case b),
    ...) and ``quantities`` ((name, metric of a, metric of b), ...); per pair and quantity both
    values and the signed relative difference (a - b) / |b|. Reported."""
    out_rows, values = [], []
    available = False
    for label, name_a, name_b in analysis.settings["pairs"]:
        row_a, row_b = rows.get(name_a), rows.get(name_b)
        for quantity, metric_a, metric_b in analysis.settings["quantities"]:
            a = None if row_a is None else _metric(row_a, metric_a)
            b = None if row_b is None else _metric(row_b, metric_b)
            if a is None or b is None:
                missing, row = (name_a, row_a) if a is None else (name_b, row_b)
                why = "case not run" if row is None else _unavailable_message(row)
                out_rows.append({"cells": [label, quantity, _fmt(a), _fmt(b), "–", f"unavailable ({missing}): {why}"]})
                values.append({"pair": label, "quantity": quantity, "verdict": UNAVAILABLE})
                continue
            available = True
            difference = (a - b) / abs(b) if b else math.inf
            values.append({"pair": label, "quantity": quantity, "a": a, "b": b, "difference": difference})
            out_rows.append({"cells": [label, quantity, _fmt(a), _fmt(b), _percent(difference), ""]})
    return {
        "columns": ["pair", "quantity", "a", "b", "(a - b) / b", "note"],
        "rows": out_rows,
        "status": REPORTED if available else UNAVAILABLE,
        "notes": [],
        "values": {"rows": values},
    }


def _size_pct(x: float | None) -> str:
    """An unsigned error size (an FE error estimate has no sign), in %."""
    return "–" if x is None or not math.isfinite(x) else f"{100.0 * x:.2f} %"


def _field_estimate(level_rows: list[dict[str, Any]], dofs: list[float], layers: list[int | None], extra: dict[str, Any] | None, k: int = -1):
    """The pressure field's estimated L2 error on each mesh (verification.fe_convergence.field_errors
    on the finest three meshes that contain it, as the quantities) and that of the extra (P1) run
    (its difference from the finest plus the finest's error), at time point ``k``, read from the
    result directories, as (finest three's estimate, each mesh's error, its record, the extra's
    error); None when a row does not say where they are."""
    from verification.fe_convergence import field_difference, field_errors, finest_windows, window_estimates

    dirs = _result_dirs(level_rows + ([extra] if extra is not None else []))
    if dirs is None:
        return None

    def estimate(j: int, sizes: tuple[float, ...]):
        a, b, c = dirs[j:j + 3]
        return field_errors(sizes, (field_difference(a, c, k), field_difference(b, c, k)), field_difference(a, b, k))

    ests = window_estimates(dofs, layers, estimate)
    errors, record = _levels_record(list(ests), finest_windows(len(level_rows)))
    extra_error = None if extra is None else field_difference(dirs[-1], dirs[len(level_rows) - 1], k) + errors[-1]
    return ests[-1], errors, record, extra_error


def _error_scale(est: Any) -> float:
    """What a Richardson estimate's relative errors are relative to
    (verification.fe_convergence.richardson): |f0|, or the finest value's magnitude outside the
    asymptotic range (the largest value's where f0 is 0)."""
    if est.asymptotic:
        return abs(est.extrapolated) if est.extrapolated else max(abs(v) for v in est.values)
    return abs(est.values[-1])


def _level_estimates(dofs: list[float], values: list[float], layers: list[int | None]):
    """One quantity on a point's meshes (verification.fe_convergence.level_estimates): the finest
    three's estimate, each mesh's error and the quantity's record (:func:`_levels_record`)."""
    from verification.fe_convergence import finest_windows, level_estimates

    ests = level_estimates(dofs, values, layers)
    errors, record = _levels_record(list(ests), finest_windows(len(values)))
    return ests[-1], errors, {**record, "values": list(values)}


def _levels_record(ests: list[Any], firsts: tuple[int, ...]) -> tuple[list[float], dict[str, Any]]:
    """Each mesh's error from its estimate (``ests[i]`` on the three meshes from ``firsts[i]``,
    verification.fe_convergence.finest_windows), and the record of a quantity: the finest three's
    estimate (order, extrapolation, asymptotic), with, past three meshes, every mesh's error and
    the first of the three meshes it was estimated from (``estimated_from``)."""
    errors = [est.errors[i - j] for i, (est, j) in enumerate(zip(ests, firsts))]
    record = ests[-1].to_dict()
    if len(ests) > 3:
        record.update(errors=errors, estimated_from=list(firsts))
    return errors, record


def _result_dirs(rows: list[dict[str, Any]]) -> list[Path] | None:
    """Each row's first result directory; None when a row does not say where it is."""
    if any(not r.get("out_dir") or not r.get("result_dirs") for r in rows):
        return None
    return [Path(r["out_dir"]) / r["result_dirs"][0] for r in rows]


def _values_by_time(rows: list[dict[str, Any]]) -> list[list[dict[str, Any]]]:
    """Per time point, each row's study values (verification.fe_convergence.fe_values): the rows'
    metrics when they hold one time point (or do not say where their results are), else each
    time point measured from the result directories. The load of each time point is "load_n"."""
    from verification.fe_convergence import fe_values, time_point_count

    dirs = _result_dirs(rows)
    n = 1 if dirs is None else time_point_count(dirs[0])
    if n == 1:
        return [[dict(r["metrics"]) for r in rows]]
    from edem.resultdir import read_result_dir

    result = read_result_dir(dirs[-1])
    series = result.timeseries
    loads = np.linalg.norm(np.column_stack([series[f"force_{x}_n"] for x in "xyz"]), axis=1)
    return [[{**fe_values(d, k), "load_n": float(loads[k]), "time_s": float(result.time_s[k])} for d in dirs] for k in range(n)]


def fe_convergence_analysis(analysis, rows: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Per point and quantity: the meshes' values, order, extrapolation and errors; the errors
    keyed for :func:`verification.fe_convergence.fe_relative_error` in ``values["entries"]``.
    A point of more than three meshes takes each mesh's error from the finest three that contain
    it (verification.fe_convergence.level_estimates), its order and extrapolation from the finest
    three. A point whose FE run has several time points (loads) is estimated at each, one row per
    quantity and load, and each mesh's error is the largest over them (as a comparison's error
    is its largest over the time points); on a history's unloading branch each quantity's errors
    are taken against its largest value in the cycle so far, as the comparisons' are
    (verification.metrics.against_cycle_peak)."""
    from verification.fe_convergence import QUANTITIES, fe_key
    from verification.metrics import unloading_branch

    out_rows, entries, points, notes = [], {}, [], []
    for point in analysis.settings["points"]:
        level_rows = [rows.get(n) for n in point["levels"]]
        missing = [n for n, r in zip(point["levels"], level_rows) if r is None or any(s.get("status") != OK for s in r.get("sides", []))]
        if missing:
            why = "case not run" if level_rows[point["levels"].index(missing[0])] is None else _unavailable_message(rows[missing[0]])
            out_rows.append({"cells": [point["point"], "all", f"unavailable: {missing[0]}: {why}", "–", "–", "–", "–", "–", "–"]})
            points.append({"point": point["point"], "unavailable": why})
            continue
        metrics = [r["metrics"] for r in level_rows]
        dofs = [float(m["fe_n_dofs"]) for m in metrics]
        if not all(a < b for a, b in zip(dofs, dofs[1:])):
            # e.g. a 1 mm layer: one element through it at 2.0 and at 1.0 mm, the same mesh twice
            why = "meshes not distinct: the mesher gave " + ", ".join(f"{d / 1e3:.0f}k" for d in dofs) + " DOFs, no three-level estimate"
            out_rows.append({"cells": [point["point"], "all", why, "–", "–", "–", "–", "–", "–"]})
            points.append({"point": point["point"], "unavailable": why})
            continue
        layers = [r["options"].get("layers_through_thickness") for r in level_rows]  # one number for all: refined in plane only
        extra = rows.get(point["extra"]) if point.get("extra") else None
        extra_ok = extra is not None and all(s.get("status") == OK for s in extra.get("sides", []))
        by_time = _values_by_time(level_rows + ([extra] if extra_ok else []))
        several = len(by_time) > 1
        level_errors: list[dict[str, float]] = [{} for _ in level_rows]
        extra_errors: dict[str, float] = {}
        record = {"point": point["point"], "mesh_sizes_mm": [r["options"]["mesh_size_mm"] for r in level_rows], "dofs": dofs,
                  "wall_time_s": [float(m["fe_wall_time_s"]) for m in metrics], "peak_memory_mb": [m.get("fe_peak_memory_mb") for m in metrics], "quantities": {}}
        cost = [", ".join(f"{d / 1e3:.0f}k" for d in dofs),
                ", ".join(f"{t:.0f} s / {_fmt(None if mem is None or not math.isfinite(float(mem)) else float(mem) / 1e3, 2)} GB" for t, mem in zip(record["wall_time_s"], record["peak_memory_mb"]))]

        def keep(error_metric: str, errors, extra_error: float | None) -> None:  # the largest over the time points
            for j, e in enumerate(errors):
                level_errors[j][error_metric] = max(e, level_errors[j].get(error_metric, 0.0))
            if extra_error is not None:
                extra_errors[error_metric] = max(extra_error, extra_errors.get(error_metric, 0.0))

        repeated = several and len({at[0]["load_n"] for at in by_time}) < len(by_time)  # a history: its time points by time
        # On a history's unloading branch the comparisons take their errors against the FE's peak in
        # the cycle (verification.metrics.against_cycle_peak); the FE's own error there is taken the
        # same way, so that the band and the reference's error are in one measure. (The pressure
        # field's stays against that instant's field: larger, on the safe side.)
        down = unloading_branch([at[0]["load_n"] for at in by_time]) if repeated else np.zeros(len(by_time), bool)
        peak_so_far: dict[str, float] = {}
        for k, at in enumerate(by_time):
            label = (f" at t = {_fmt(at[0]['time_s'])} s ({_fmt(at[0]['load_n'])} N)" if repeated else f" at {_fmt(at[0]['load_n'])} N") if several else ""
            for quantity, (value_metric, error_metric) in QUANTITIES.items():
                values = [float(m[value_metric]) for m in at[:len(level_rows)]]
                est, errors, record["quantities"][quantity + label] = _level_estimates(dofs, values, layers)
                scale = _error_scale(est)
                peak = peak_so_far[quantity] = max(peak_so_far.get(quantity, 0.0), scale)
                to_peak = scale / peak if down[k] and peak > 0.0 else 1.0
                extra_error = None
                if extra_ok:
                    v = float(at[-1][value_metric])
                    ref = est.extrapolated if est.asymptotic else values[-1]
                    spread = 0.0 if est.asymptotic else errors[-1]
                    extra_error = (abs(v - ref) / abs(ref) + spread) * to_peak
                    record["quantities"][quantity + label].update(p1_value=v, p1_error=extra_error)
                errors = [e * to_peak for e in errors]
                if down[k]:
                    record["quantities"][quantity + label].update(relative_to="cycle peak", cycle_peak_errors=errors)
                cells = [point["point"], quantity + label + (" (against the cycle's peak)" if down[k] else ""), ", ".join(_fmt(v, 4) for v in values),
                         _fmt(est.order, 3), _fmt(est.extrapolated, 4) if est.asymptotic else "not asymptotic", ", ".join(_size_pct(e) for e in errors),
                         "–" if extra_error is None else f"{_fmt(float(at[-1][value_metric]), 4)} ({_size_pct(extra_error)})"]
                keep(error_metric, errors, extra_error)
                out_rows.append({"cells": cells + cost, "flag": not est.asymptotic})
            fields = _field_estimate(level_rows, dofs, layers, extra if extra_ok else None, k if several else -1)
            if fields is not None:
                est, errors, record["quantities"]["pressure field (L2)" + label], extra_error = fields
                keep("pressure_l2_rel_error", errors, extra_error)
                if extra_error is not None:
                    record["quantities"]["pressure field (L2)" + label]["p1_error"] = extra_error
                cells = [point["point"], "pressure field (L2)" + label, "differences from the finest: " + ", ".join(_size_pct(v) for v in est.values[:2]),
                         _fmt(est.order, 3), "on a line" if est.asymptotic else "not asymptotic", ", ".join(_size_pct(e) for e in errors),
                         "–" if extra_error is None else f"({_size_pct(extra_error)})"]
                out_rows.append({"cells": cells + cost, "flag": not est.asymptotic})
        last = by_time[-1][:len(level_rows)]
        ratios = [float(m["fe_peak_pressure_mpa"]) / float(m["fe_p98_pressure_mpa"]) if float(m["fe_p98_pressure_mpa"]) > 0 else math.nan for m in last]
        record["peak_over_p98"] = ratios
        notes.append(f"{point['point']}: raw peak / 98th percentile by area = {', '.join(_fmt(r, 3) for r in ratios)} on its meshes "
                     + (f"at {_fmt(by_time[-1][0]['load_n'])} N " if several else "") + ("(a few nodes set the raw peak)" if max(ratios) > 1.2 else "(a smooth maximum)"))
        for name, row, errors in zip(point["levels"], level_rows, level_errors):
            entries[fe_key(point["scene"], point["side"], point["overrides"], row["options"])] = {"case": name, "errors": errors}
        if extra_ok:
            entries[fe_key(point["scene"], point["side"], point["overrides"], extra["options"])] = {"case": point["extra"], "errors": extra_errors}
        points.append(record)
    notes.extend(analysis.settings.get("findings", []))
    notes.append("Values coarsest mesh first; h ~ N_dofs^(-1/3) represents each mesh (the mesher halves M's triangles and sets ceil(t / size) layers, so the "
                 "refinement ratios differ), h ~ N_dofs^(-1/2) three meshes of one number of elements through the layers (refined in plane only); order from "
                 "f(h) = f0 + C h^p through three values; error of each mesh |f_i - f0| / |f0|. Not asymptotic (flagged): "
                 "the differences change sign or the order is outside 0.5-4; each mesh's error is then the largest difference to the other meshes. A point "
                 "of four meshes: each mesh's error from the finest three that contain it (the coarsest from the first three), the order and extrapolation "
                 "shown from the finest three. A point solved at several loads (its time points) is estimated at each; its stored error is the largest over them. "
                 "On a history's unloading branch a quantity's errors are taken against its largest value in the cycle so far, as the comparisons' are "
                 "(verification.metrics.against_cycle_peak); the pressure field's against that instant's field.")
    notes.append("P1 column: quick's P1 reference at 1.0 mm and its error against the extrapolation (against the finest mesh plus that mesh's error when not asymptotic).")
    return {
        "columns": ["point", "quantity", "values (coarsest first)", "order", "extrapolated", "error of each mesh", "P1 1.0 mm (error)", "DOFs", "time / peak memory"],
        "rows": out_rows,
        "status": REPORTED if entries else UNAVAILABLE,
        "notes": notes,
        "values": {"points": points, "entries": entries},
    }


ANALYSES: dict[str, Callable[[Any, dict[str, dict[str, Any]]], dict[str, Any]]] = {
    "order": order_analysis,
    "thesis": thesis_analysis,
    "sensitivity": sensitivity_analysis,
    "table": table_analysis,
    "pareto": pareto_analysis,
    "goal": goal_analysis,
    "trust": trust_analysis,
    "fe-band": fe_band_analysis,
    "per-load": per_load_analysis,
    "pairs": pairs_analysis,
    "fe-convergence": fe_convergence_analysis,
}


def run_analysis(analysis, rows: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """The analysis's table over the case rows; a crash becomes status "error" with its message."""
    try:
        result = ANALYSES[analysis.kind](analysis, rows)
    except Exception as exc:  # a bug in an analysis must not sink the campaign's report

        result = {"columns": [], "rows": [], "status": ERROR, "notes": [f"{type(exc).__name__}: {exc}", traceback.format_exc()[-1200:]], "values": {}}
    return {"name": analysis.name, "title": analysis.title, "kind": analysis.kind, **result}


def format_analysis(result: dict[str, Any]) -> str:
    """Plain-text table of an analysis (what `edem verify` prints)."""
    lines = [f"{result['title']} [{result['status']}]"]
    columns = result.get("columns", [])
    table = [columns] + [r["cells"] for r in result.get("rows", [])]
    if columns:
        widths = [max(len(str(r[i])) for r in table) for i in range(len(columns))]
        for k, r in enumerate(table):
            mark = "!" if k and result["rows"][k - 1].get("flag") else " "
            lines.append(mark + " " + "  ".join(str(c).ljust(w) for c, w in zip(r, widths)).rstrip())
    if result["status"] == ERROR:
        lines += result.get("notes", [])[:1]
    return "\n".join(lines)
