"""One HTML page per campaign (docs/campaigns.md, docs/result-format.md): cases, verdicts, figures, scenes, versions, run times.

:func:`write_campaign_report` takes the campaign summary of :func:`verification.runner.run_campaign`
(the content of the campaign's metrics.json) and writes ``report.html`` next to it, with its
figures as PNG files under ``figures/`` and relative links to every case's metrics.json, result
directories and ``pressure.pvd`` (open those in ParaView). Figures are redrawn only when their
inputs changed (``figures/index.json``). matplotlib and pyvista are imported only here.
"""

from __future__ import annotations

import hashlib
import html
import json
import math
import textwrap
from pathlib import Path
from typing import Any

import numpy as np

from edem.resultdir import read_timeseries_csv
from reports.maps import render_pressure_maps
from reports.plots import axis_label, figure_legend, fit_title, plot_timeseries
from verification.analyses import grid_of, per_time_comparison
from verification.campaigns import instant_indices
from verification.status import Status
from verification.verdicts import CASE_VERDICTS, FE_ERROR_UNKNOWN, FE_TOO_COARSE, NOT_JUDGED, VERDICT_MEANINGS, headline

#: case verdicts (verification.verdicts) and analysis statuses
STATUS_COLOURS = {Status.VERIFIED: "#1b7f3a", Status.FLAGGED: "#c05600", Status.FE_NOT_CONVERGED: "#6a3d9a", Status.REFUSED_AS_DECLARED: "#1b5e9a",
                  Status.RAN: "#555555", Status.REPORTED: "#555555", Status.FAILED: "#b3261e", Status.ERROR: "#b3261e", Status.UNAVAILABLE: "#8a6d00"}
#: a table longer than this many rows is folded (<details>) below the figures and analyses
LONG_TABLE_ROWS = 12


def _value(v: Any) -> float:
    return float(v) if v is not None else math.nan


def _fmt(v: Any) -> str:
    if v is None:
        return "–"
    try:
        x = float(v)
    except (TypeError, ValueError):
        return html.escape(str(v))
    if math.isnan(x):
        return "nan"
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return f"{x:.4g}"


def _fmt_metric(metric: str, v: Any) -> str:
    """A metric's value; a signed relative error with its sign (+0.13, -0.43: the L2 error is a norm)."""
    signed = metric.endswith("_rel_error") and metric != "pressure_l2_rel_error"
    if signed and isinstance(v, (int, float)) and math.isfinite(v):
        return f"{float(v):+.4g}"
    return _fmt(v)


def _matplotlib():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


# ---------------------------------------------------------------------------------------------
# Figures


def side_label(row: dict[str, Any], side: str) -> str:
    """A side of a case as its figures name it: a discrete side with its bed's label (edem.beds:
    "dem, coupled layer"; the key's value, "thin-layer", is no name), an FE side as it is."""
    from edem.beds import BEDS

    coupling = (row.get("overrides") or {}).get("cartilage.coupling")
    return f"{side}, {BEDS[coupling].label}" if coupling in BEDS and not side.startswith("fe-") else side


def _histogram_figure(spec: dict[str, Any], rows: dict[str, dict[str, Any]], path: Path) -> None:
    """kind "histogram": the distribution of each metric of y over the cases, one panel each,
    with its median and 5-95 % range."""
    plt = _matplotlib()
    names = [n for n in spec["cases"] if n in rows]
    panels = list(spec["y"])
    fig, axes = plt.subplots(1, len(panels), figsize=(4.6 * len(panels), 3.6), constrained_layout=True, squeeze=False)
    for ax, metric in zip(axes[0], panels):
        ys = np.array([_value(rows[n]["metrics"].get(metric)) for n in names])
        ys = ys[np.isfinite(ys)]
        if ys.size:
            ax.hist(ys, bins=max(5, int(np.sqrt(ys.size))), color="tab:blue", alpha=0.8)
            lo, mid, hi = np.percentile(ys, [5, 50, 95])
            ax.axvline(mid, color="k", label=f"median {mid:.3g}")
            ax.axvspan(lo, hi, color="grey", alpha=0.2, label=f"5-95 %: {lo:.3g} to {hi:.3g}")
        _finish_panel(ax, False, False, axis_label(metric), f"cases (of {len(names)})", legend=True)
    _save(plt, fig, spec["title"], path)


def _sweep_figure(spec: dict[str, Any], rows: dict[str, dict[str, Any]], path: Path) -> None:
    """Metrics of a series of cases against one of their parameters, one panel per metric
    (kind "sweep": joined in order; kind "scatter": one unjoined point per case, e.g. a population)."""
    plt = _matplotlib()
    names = [n for n in spec["cases"] if n in rows]
    xs = np.array([_value(rows[n]["params"].get(spec["x"])) for n in names])
    panels = list(spec["y"])
    logy = spec["logy"] if isinstance(spec["logy"], (list, tuple)) else [spec["logy"]] * len(panels)
    exact = spec.get("exact") or {}
    # several series of cases on each panel (e.g. two models against one reference), else one
    series = [(label, [n for n in group if n in rows]) for label, group in spec.get("series") or ()] or [(None, names)]
    fig, axes = plt.subplots(1, len(panels), figsize=(4.6 * len(panels), 3.6), constrained_layout=True, squeeze=False)
    for ax, metric, log in zip(axes[0], panels, logy):
        for label, group in series:
            gx = np.array([_value(rows[n]["params"].get(spec["x"])) for n in group])
            ys = np.array([_value(rows[n]["metrics"].get(metric)) for n in group])
            ys = np.abs(ys) if log else ys  # signed errors: their magnitude on a log axis
            ok = np.isfinite(gx) & np.isfinite(ys) & ((ys > 0) if log else True)
            if spec["kind"] == "scatter":
                ax.plot(gx[ok], ys[ok], "o", markersize=3, alpha=0.6, label=label or axis_label(metric, magnitude=log))
            else:
                ax.plot(gx[ok], ys[ok], "o-", label=label or axis_label(metric, magnitude=log))
        # A sanity bound (1000 %, it catches a broken run) makes no accuracy claim: not drawn
        # beside the errors as if it were their tolerance.
        tols = [(x, rows[n]["tolerance"].get(metric)) for x, n in zip(xs, names)
                if (rows[n].get("verdicts") or {}).get(metric, {}).get("kind") != "sanity"]
        tols = [(x, t) for x, t in tols if t is not None and math.isfinite(t)]
        if tols:  # a tolerance bounds |error|: drawn at +-t on a linear axis
            ax.plot([x for x, _ in tols], [t for _, t in tols], "k_", markersize=14, mew=2, label="tolerance")
            if not log and metric.endswith("_rel_error") and metric != "pressure_l2_rel_error":
                ax.plot([x for x, _ in tols], [-t for _, t in tols], "k_", markersize=14, mew=2)
        if metric in exact:
            ax.axhline(exact[metric], color="grey", ls=":", label=f"exact {exact[metric]:g}")
        for line_metric, value, text in spec.get("lines") or ():
            if line_metric == metric:
                ax.axhline(value, color="grey", ls="--", lw=0.8, label=text)
        slope = spec.get("reference_slope")
        if slope is not None and ok.sum() >= 1:  # through the first point of the (last) series
            x0, y0 = gx[ok][0], ys[ok][0]
            xr = np.array([gx[ok].min(), gx[ok].max()])
            ax.plot(xr, y0 * (xr / x0) ** slope, ":", color="grey", label=f"slope {slope:g}")
        _finish_panel(ax, spec["logx"], log, axis_label(spec["x"]), axis_label(metric, magnitude=log))
    _save(plt, fig, spec["title"], path, axes)


def _series_per_time(spec: dict[str, Any], rows: dict[str, dict[str, Any]]) -> list[tuple[str, str, list[dict[str, Any]]]]:
    """(label, case, its comparison at each load, by load) for each case of each series of a
    figure of kind "area-vs-load" or "per-load"; ValueError when none has a comparison."""
    out = []
    for label, group in spec.get("series") or [(n, (n,)) for n in spec["cases"]]:
        for name in group:
            per_time = per_time_comparison(rows[name]) if name in rows else None
            if per_time:
                out.append((label, name, sorted(per_time, key=lambda e: e["load_n"])))
    if not out:
        raise ValueError("no case of the figure has a comparison over its loads")
    return out


def _area_load_figure(spec: dict[str, Any], rows: dict[str, dict[str, Any]], path: Path) -> None:
    """kind "area-vs-load": the contact area of both sides of each case against the load (its
    time points): side a solid, one line per series; side b (the FE) dashed, once per distinct
    curve (cases sharing one FE run share its line)."""
    plt = _matplotlib()
    fig, ax = plt.subplots(figsize=(7.2, 4.6), constrained_layout=True)
    drawn: set[tuple[float, ...]] = set()
    for k, (label, _name, per_time) in enumerate(_series_per_time(spec, rows)):
        loads = [e["load_n"] for e in per_time]
        colour = f"C{k}"
        ax.plot(loads, [e["contact_area_a_mm2"] for e in per_time], "o-", color=colour, label=f"{label}: DEM")
        fe = tuple(round(e["contact_area_b_mm2"], 6) for e in per_time)
        if fe not in drawn:
            drawn.add(fe)
            ax.plot(loads, fe, "s--", color=colour, mfc="none", label=f"{label.split(',')[0]}: FE")
    _finish_panel(ax, False, False, "load (N)", "contact area (mm²)")
    _save(plt, fig, spec["title"], path, ax)


def _per_load_figure(spec: dict[str, Any], rows: dict[str, dict[str, Any]], path: Path) -> None:
    """kind "per-load": each comparison metric of ``y`` at each load of each case (its time
    points), one panel per metric, one line per series, the case's tolerance as bars at +-t."""
    plt = _matplotlib()
    panels = list(spec["y"])
    fig, axes = plt.subplots(1, len(panels), figsize=(4.6 * len(panels), 4.2), constrained_layout=True, squeeze=False)
    entries = _series_per_time(spec, rows)
    for ax, metric in zip(axes[0], panels):
        for k, (label, _name, per_time) in enumerate(entries):
            ax.plot([e["load_n"] for e in per_time], [_value(e.get(metric)) for e in per_time], "o-", color=f"C{k}", label=label)
        loads = sorted({e["load_n"] for _l, _n, per_time in entries for e in per_time})
        tols = {rows[name]["tolerance"].get(metric) for _l, name, _p in entries} - {None}
        for t in tols:
            ax.plot(loads + loads, [t] * len(loads) + [-t] * len(loads), "k_", markersize=14, mew=2, label="model band")
        ax.axhline(0.0, color="grey", lw=0.6)
        _finish_panel(ax, False, False, "load (N)", axis_label(metric))
    _save(plt, fig, spec["title"], path, axes)


def _error_time_figure(spec: dict[str, Any], rows: dict[str, dict[str, Any]], path: Path) -> None:
    """kind "error-vs-time": each metric of y against the wall time of side a (one panel per
    metric, log axes as declared), one series per family of cases (the case name up to its last
    '-'), dashed the Pareto front (points no other beats in both) of the cases against each truth
    (side b)."""
    plt = _matplotlib()
    names = [n for n in spec["cases"] if n in rows and rows[n].get("sides")]
    panels = list(spec["y"])
    fig, axes = plt.subplots(1, len(panels), figsize=(4.8 * len(panels), 3.8), constrained_layout=True, squeeze=False)
    for ax, metric in zip(axes[0], panels):
        points = []
        for n in names:
            t, e = _value(rows[n]["sides"][0].get("wall_time_s")), _value(rows[n]["metrics"].get(metric))
            e = abs(e) if spec["logy"] else e  # signed errors: their magnitude on a log axis
            if math.isfinite(t) and math.isfinite(e) and t > 0 and (e > 0 or not spec["logy"]):
                truth = rows[n]["sides"][1].get("side", "") if len(rows[n]["sides"]) > 1 else ""
                points.append((n.rsplit("-", 1)[0], n, t, e, truth))
        for family in dict.fromkeys(p[0] for p in points):
            mine = sorted((p for p in points if p[0] == family), key=lambda p: p[2])
            ax.plot([p[2] for p in mine], [p[3] for p in mine], "o-", label=family)
            for p in mine:
                ax.annotate(p[1].rsplit("-", 1)[1], (p[2], p[3]), fontsize=6, xytext=(3, 3), textcoords="offset points")
        for k, truth in enumerate(dict.fromkeys(p[4] for p in points)):  # one front per truth (side b)
            group = [p for p in points if p[4] == truth]
            front = sorted((p for p in group if not any(q[2] <= p[2] and q[3] <= p[3] and (q[2] < p[2] or q[3] < p[3]) for q in group)), key=lambda p: p[2])
            if front:
                ax.plot([p[2] for p in front], [p[3] for p in front], "--", color=f"{0.2 * k:.1f}", lw=1, label=f"Pareto front vs {truth or 'b'}")
        _finish_panel(ax, spec["logx"], spec["logy"], "wall time of side a (s)", axis_label(metric, magnitude=spec["logy"]))
    _save(plt, fig, spec["title"], path, axes)


#: characters of a y-axis label on one line: longer labels wrap, so that they stay within the panel's
#: height (about 36 characters of 10 pt text fit along a 3.6 in panel's axis)
YLABEL_CHARS = 36


def _finish_panel(ax: Any, logx: bool, logy: bool, xlabel: str, ylabel: str, legend: bool = False) -> None:
    """Scales, labels and grid of a panel; ``legend``: its own legend (where the panels' entries
    differ, e.g. a histogram's median), else the figure's one below the panels (:func:`_save`)."""
    if logx:
        ax.set_xscale("log")
    if logy:
        ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    # "(a − b)" is one word to the wrapping: no line ends inside it
    ax.set_ylabel(textwrap.fill(ylabel.replace("a − b", "a\u00a0−\u00a0b"), YLABEL_CHARS, break_on_hyphens=False))
    ax.grid(alpha=0.3, which="both")
    if legend:
        ax.legend(fontsize=8)


def _save(plt: Any, fig: Any, title: str, path: Path, axes: Any = None) -> None:
    """Title (wrapped to the figure), the panels' legend below them (``axes``), written to ``path``."""
    if axes is not None:
        figure_legend(fig, axes)
    fit_title(fig, title)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _timeseries_figure(spec: dict[str, Any], rows: dict[str, dict[str, Any]], out_dir: Path, path: Path) -> None:
    dirs, labels = [], []
    for name in spec["cases"]:
        row = rows.get(name)
        if row is None:
            continue
        for rel, side in zip(row["result_dirs"], [s for s in row["sides"] if s.get("result_dir")]):
            dirs.append(out_dir / rel)
            labels.append(f"{name}: {side_label(row, side['side'])}")
    if not dirs:
        raise ValueError("no result directory to plot")
    plot_timeseries(dirs, spec["column"], path, labels)


def _grid_figure(spec: dict[str, Any], rows: dict[str, dict[str, Any]], path: Path) -> None:
    """kind "heatmap": the metric y[0] over the grid of params x and param2; kind "cuts": line cuts
    of it against x at the lowest, middle and highest param2, and against param2 likewise."""
    plt = _matplotlib()
    metric = spec["y"][0]
    xs, ys, z = grid_of(rows, tuple(spec["cases"]), spec["x"], spec["param2"], metric)
    if not np.isfinite(z).any():
        raise ValueError("no case of the grid has a value")
    label_x, label_y, label_z = (axis_label(v) for v in (spec["x"], spec["param2"], metric))
    if spec["kind"] == "heatmap":
        fig, ax = plt.subplots(figsize=(6.8, 5.2), constrained_layout=True)
        mesh = ax.pcolormesh(xs, ys, z.T, shading="nearest", cmap="viridis")
        levels = ax.contour(xs, ys, z.T, colors="white", linewidths=0.7, levels=8)
        ax.clabel(levels, fontsize=7, fmt="%.3g")
        fig.colorbar(mesh, ax=ax, label=label_z)
        ax.set_xlabel(label_x)
        ax.set_ylabel(label_y)
    else:
        fig, axes = plt.subplots(1, 2, figsize=(10.5, 4.0), constrained_layout=True)
        for j in sorted({0, len(ys) // 2, len(ys) - 1}):
            axes[0].plot(xs, z[:, j], "o-", ms=3, label=f"{label_y} = {ys[j]:.4g}")
        for i in sorted({0, len(xs) // 2, len(xs) - 1}):
            axes[1].plot(ys, z[i, :], "o-", ms=3, label=f"{label_x} = {xs[i]:.4g}")
        for ax, xlabel in ((axes[0], label_x), (axes[1], label_y)):
            ax.set_xlabel(xlabel)
            ax.set_ylabel(label_z)
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8)
    _save(plt, fig, spec["title"], path)


def _instant_times(spec: dict[str, Any], row: dict[str, Any], out_dir: Path) -> list[tuple[str, float, float]]:
    """(label, time_s, % of the span) of each instant of a "maps" figure, from side a's time series."""
    series = read_timeseries_csv(out_dir / row["result_dirs"][0] / "timeseries.csv")
    time = series["time_s"]
    force = np.column_stack([series[f"force_{x}_n"] for x in "xyz"])
    instants = [tuple(i) for i in spec["instants"]]
    span = float(time[-1] - time[0]) or 1.0
    return [(label, float(time[k]), 100.0 * float(time[k] - time[0]) / span) for (label, _), k in zip(instants, instant_indices(time, force, tuple(instants)))]


def _wall_time_figure(rows: list[dict[str, Any]], path: Path) -> None:
    plt = _matplotlib()
    if len(rows) > 60:  # hundreds of cases: a histogram reads better than hundreds of bars
        times = np.array([max(r["wall_time_s"], 1e-4) for r in rows])
        fig, ax = plt.subplots(figsize=(7, 3.4), constrained_layout=True)
        bins = np.geomspace(times.min(), times.max() * 1.001, 30) if times.max() > times.min() else 10
        ax.hist(times, bins=bins, color="#1b7f3a")
        ax.set_xscale("log")
        ax.set_xlabel(f"wall time of a case (s), {len(rows)} cases, total {times.sum():.1f} s")
        ax.set_ylabel("cases")
        ax.grid(alpha=0.3, which="both")
        fig.savefig(path, dpi=110)
        plt.close(fig)
        return
    names = [r["name"] for r in rows]
    times = [max(r["wall_time_s"], 1e-4) for r in rows]
    colours = [STATUS_COLOURS.get(r["status"], "grey") for r in rows]
    fig, ax = plt.subplots(figsize=(7, 0.9 + 0.18 * len(rows)), constrained_layout=True)
    ax.barh(np.arange(len(rows)), times, color=colours)
    ax.set_yticks(np.arange(len(rows)), names, fontsize=7)
    ax.invert_yaxis()
    ax.set_xscale("log")
    ax.set_xlabel("wall time of the case (s; coloured by its verdict, as in the legend)")
    ax.grid(alpha=0.3, axis="x", which="both")
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _figure_key(*parts: Any) -> str:
    return hashlib.sha256(json.dumps(parts, sort_keys=True, default=str).encode()).hexdigest()


def _make_figures(summary: dict[str, Any], out_dir: Path) -> list[dict[str, str]]:
    """Draw (or reuse) every figure; returns [{"file", "title", "error"}] in report order."""
    fig_dir = out_dir / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    index_path = fig_dir / "index.json"
    try:
        index = json.loads(index_path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        index = {}
    rows = {r["name"]: r for r in summary["cases"]}
    keys = {r["name"]: (r["metrics"], r["status"], r["wall_time_s"] if not r["cached"] else None) for r in summary["cases"]}
    jobs = []
    for spec in summary.get("figures", []):
        involved = [keys.get(n) for n in spec["cases"]]
        present = [rows[n] for n in spec["cases"] if n in rows]
        if present and all(r["status"] in (Status.UNAVAILABLE, Status.ERROR) or not r["result_dirs"] for r in present):
            why = next((s["message"].splitlines()[0] for s in present[0]["sides"] if s["status"] != Status.OK and s.get("message")), present[0]["status"])
            jobs.append((spec["name"], spec["title"], {"kind": "note", "error": f"case {present[0]['name']} is {present[0]['status']}: {why}", "unavailable": True}, None))
            continue
        if spec["kind"] == "maps":
            row = present[0]
            if len(row["result_dirs"]) < 2:
                why = next((f"{s['side']} {s['status']}: {s['message'].splitlines()[0]}" for s in row["sides"] if s["status"] != Status.OK and s.get("message")), "one side wrote no result directory")
                jobs.append((spec["name"], spec["title"], {"kind": "note", "error": f"not drawn: {why}", "unavailable": True}, None))
                continue
            if not spec.get("instants"):
                jobs.append((spec["name"], spec["title"], {"kind": "maps", "case": row["name"]}, involved))
                continue
            try:
                instants = _instant_times(spec, row, out_dir)
            except Exception as exc:
                jobs.append((spec["name"], spec["title"], {"kind": "note", "error": f"{type(exc).__name__}: {exc}", "unavailable": False}, None))
                continue
            labels = [side_label(row, s["side"]) for s in row["sides"][:2]]
            for k, (label, time_s, percent) in enumerate(instants):
                title = f"{spec['title']}: {label}, {percent:.0f} % stance (t = {time_s:.3g} s)"
                job = {"kind": "maps-at", "case": row["name"], "time_s": time_s, "labels": labels, "caption": f"{label}: {percent:.0f} % stance (t = {time_s:.3g} s)"}
                jobs.append((f"{spec['name']}-{k}", title, job, involved))
            continue
        jobs.append((spec["name"], spec["title"], spec, involved))
    for row in summary["cases"]:
        if row.get("maps") and len(row["result_dirs"]) == 2:
            jobs.append((f"{row['name']}-maps", f"{row['name']}: pressure maps, {' vs '.join(side_label(row, s['side']) for s in row['sides'])}", {"kind": "maps", "case": row["name"]}, [keys[row["name"]]]))
    jobs.append(("wall-times", "Wall time per case", {"kind": "wall-times"}, [(r["name"], r["wall_time_s"], r["status"]) for r in summary["cases"]]))

    figures = []
    for name, title, spec, inputs in jobs:
        if spec["kind"] == "note":  # nothing to draw: say why
            figures.append({"name": name, "file": "", "title": title, "error": spec["error"], "unavailable": spec["unavailable"]})
            continue
        file = f"{name}.png"
        path = fig_dir / file
        key = _figure_key(spec, inputs)
        error = ""
        if not (path.is_file() and index.get(name) == key):
            try:
                if spec["kind"] in ("sweep", "scatter"):
                    _sweep_figure(spec, rows, path)
                elif spec["kind"] == "histogram":
                    _histogram_figure(spec, rows, path)
                elif spec["kind"] == "timeseries":
                    _timeseries_figure(spec, rows, out_dir, path)
                elif spec["kind"] == "error-vs-time":
                    _error_time_figure(spec, rows, path)
                elif spec["kind"] == "area-vs-load":
                    _area_load_figure(spec, rows, path)
                elif spec["kind"] == "per-load":
                    _per_load_figure(spec, rows, path)
                elif spec["kind"] == "maps":
                    row = rows[spec["case"]]
                    render_pressure_maps(out_dir / row["result_dirs"][0], out_dir / row["result_dirs"][1], path, labels=tuple(side_label(row, s["side"]) for s in row["sides"][:2]))
                elif spec["kind"] == "maps-at":
                    row = rows[spec["case"]]
                    render_pressure_maps(
                        out_dir / row["result_dirs"][0], out_dir / row["result_dirs"][1], path,
                        labels=tuple(spec["labels"]), time_s=spec["time_s"], title=spec["caption"],
                    )
                elif spec["kind"] in ("heatmap", "cuts"):
                    _grid_figure(spec, rows, path)
                elif spec["kind"] == "wall-times":
                    _wall_time_figure(summary["cases"], path)
                else:
                    raise ValueError(f"unknown figure kind {spec['kind']!r}")
                index[name] = key
            except Exception as exc:  # a figure must not sink the report: say what went wrong
                error = f"{type(exc).__name__}: {exc}"
                index.pop(name, None)
                path.unlink(missing_ok=True)
        figures.append({"name": name, "file": f"figures/{file}", "title": title, "error": error})
    index_path.write_text(json.dumps(index, indent=1) + "\n", encoding="utf-8")
    return figures


# ---------------------------------------------------------------------------------------------
# The page

CSS = """
body { font-family: system-ui, sans-serif; margin: 1.5em auto; max-width: 1250px; color: #222; }
h1 { font-size: 1.5em; } h2 { font-size: 1.2em; margin-top: 1.6em; border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; font-size: 0.85em; }
td, th { border: 1px solid #ddd; padding: 3px 6px; vertical-align: top; text-align: left; }
th { background: #f3f3f3; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
.pass { color: #1b7f3a; } .fail { color: #b3261e; font-weight: bold; } .na { color: #777; }
.status { font-weight: bold; } figure { margin: 1em 0; } figure img { max-width: 100%; border: 1px solid #eee; }
code { font-size: 0.95em; } .small { font-size: 0.8em; color: #555; }
td.metrics { min-width: 24em; font-size: 0.95em; } td.links { font-size: 0.9em; }
tr.flag td { background: #fff3e0; } .analysis-status { font-weight: bold; }
.flagged { color: #c05600; font-weight: bold; } .fecoarse { color: #6a3d9a; font-weight: bold; } .why { font-size: 0.85em; color: #555; }
#trust-summary { background: #f7f9fc; border: 1px solid #d8e0ea; padding: 0.2em 1em 0.8em; }
#trust-summary li { margin: 0.3em 0; }
table.legend { margin: 0.5em 0; }
"""


def _analyses_html(analyses: list[dict[str, Any]]) -> list[str]:
    """One table per campaign-level analysis (verification.analyses): headline numbers first."""
    h = html.escape
    parts = ["<h2>Analyses</h2>"] if analyses else []
    for result in analyses:
        colour = STATUS_COLOURS.get(result["status"], "#444")
        parts.append(f'<h3>{h(result["title"])} <span class="analysis-status" style="color:{colour}">[{h(result["status"])}]</span></h3>')
        parts += _analysis_table(result)
    return parts


def _folded(parts: list[str], n_rows: int, what: str) -> list[str]:
    """``parts`` (a table's HTML) folded in a <details> when it has more than LONG_TABLE_ROWS rows."""
    if n_rows <= LONG_TABLE_ROWS:
        return parts
    return [f"<details><summary>{html.escape(what)} ({n_rows} rows): show</summary>", *parts, "</details>"]


def _analysis_table(result: dict[str, Any]) -> list[str]:
    h = html.escape
    parts = []
    if result.get("columns"):
        table = ["<table><tr>" + "".join(f"<th>{h(str(c))}</th>" for c in result["columns"]) + "</tr>"]
        for row in result["rows"]:
            cls = ' class="flag"' if row.get("flag") else ""
            table.append(f"<tr{cls}>" + "".join(f"<td>{h(str(c))}</td>" for c in row["cells"]) + "</tr>")
        table.append("</table>")
        parts += _folded(table, len(result["rows"]), "the table")
    for note in result.get("notes", []):
        parts.append(f'<p class="small">{h(str(note))}</p>')
    return parts


def _trust_html(result: dict[str, Any], figures: list[dict[str, Any]]) -> list[str]:
    """The trust summary (analysis kind "trust"): sentences, its charts (``values["figures"]``), the table."""
    h = html.escape
    parts = [f'<section id="trust-summary"><h2>{h(result["title"])}</h2>']
    sentences = result.get("values", {}).get("sentences", [])
    if sentences:
        parts.append("<ul>" + "".join(f"<li>{h(text)}</li>" for text in sentences) + "</ul>")
    wanted = result.get("values", {}).get("figures", [])
    for figure in sorted((f for f in figures if f.get("name") in wanted and f.get("file") and not f.get("error")), key=lambda f: wanted.index(f["name"])):
        parts.append(f'<figure><img src="{h(figure["file"])}" alt="{h(figure["title"])}"><figcaption>{h(figure["title"])}</figcaption></figure>')
    parts += _analysis_table(result)
    parts.append("</section>")
    return parts


def _status_cell(status: str) -> str:
    colour = STATUS_COLOURS.get(status, "#444")
    return f'<td class="status" style="color:{colour}">{html.escape(status)}</td>'


def _metrics_cell(row: dict[str, Any]) -> str:
    """Each metric; a judged one with its tolerance, and every tolerance's reason (its basis) below."""
    h = html.escape
    parts, reasons = [], {}
    # |value| against the tolerance (errors are signed); a metric with no verdict or a met sanity
    # bound is grey ("reported, not judged"), never green
    marks = {"met": ("pass", "|·| &le;"), "fail": ("fail", "|·| &gt;"), "outside band": ("flagged", "|·| &gt; band")}
    for metric, value in row["metrics"].items():
        verdict = row["verdicts"].get(metric)
        if verdict is None or verdict["verdict"] == NOT_JUDGED:
            parts.append(f'<span class="na">{h(metric)} = {_fmt_metric(metric, value)} (reported, not judged)</span>')
            continue
        if verdict["verdict"] == FE_TOO_COARSE:
            parts.append(f'<span class="fecoarse">{h(metric)} = {_fmt_metric(metric, value)}: {h(FE_TOO_COARSE)} (band {_fmt(verdict["tolerance"])} '
                         f'&le; the FE\'s estimated error {_fmt(verdict.get("fe_error"))})</span>')
            continue
        if verdict["verdict"] == FE_ERROR_UNKNOWN:
            parts.append(f'<span class="fecoarse">{h(metric)} = {_fmt_metric(metric, value)} inside the band {_fmt(verdict["tolerance"])}, '
                         f'but {h(FE_ERROR_UNKNOWN)}: its run is not in the fe-convergence study, not judged</span>')
            continue
        cls, mark = marks.get(verdict["verdict"], ("na", "vs"))
        parts.append(f'<span class="{cls}">{h(metric)} = {_fmt_metric(metric, value)} {mark} {_fmt(verdict["tolerance"])}</span>')
    for metric, verdict in row["verdicts"].items():
        if metric not in row["metrics"]:
            cls = "na" if verdict["verdict"] == "n/a" else "fail"
            parts.append(f'<span class="{cls}">{h(metric)}: {h(verdict["verdict"])} (tolerance {_fmt(verdict["tolerance"])})</span>')
        if verdict.get("reason"):
            reasons.setdefault((verdict.get("kind", ""), verdict["reason"]), []).append(metric)
    for (kind, reason), metrics in reasons.items():
        parts.append(f'<span class="why">why {h(", ".join(metrics))}: [{h(kind)}] {h(reason)}</span>')
    return '<td class="metrics">' + "<br>".join(parts) + "</td>"


def _links_cell(row: dict[str, Any]) -> str:
    links = [f'<a href="{html.escape(row["case_dir"])}/metrics.json">metrics.json</a>']
    for side in row["sides"]:
        if side.get("result_dir"):
            rel = f"{row['case_dir']}/{side['result_dir']}"
            links.append(
                f'{html.escape(side["side"])}: <a href="{html.escape(rel)}/">{html.escape(side["result_dir"])}</a> '
                f'(<a href="{html.escape(rel)}/pressure.pvd">pressure.pvd</a>, <a href="{html.escape(rel)}/summary.json">summary</a>)'
            )
        elif side["status"] != Status.OK:
            first = side["message"].splitlines()[0] if side["message"] else ""
            links.append(f'{html.escape(side["side"])}: <i>{html.escape(side["status"])}</i> {html.escape(first)}')
    return '<td class="links">' + "<br>".join(links) + "</td>"


def write_campaign_report(summary: dict[str, Any], out_dir: str | Path) -> Path:
    """Write ``out_dir/report.html`` (and its figures) for a campaign summary; returns its path.

    The page opens with its answer: the trust summary when the campaign has one (analysis kind
    "trust"), the verdict counts with what each verdict means, the figures, the other analyses;
    then the cases (every tolerance with its reason; folded when longer than LONG_TABLE_ROWS,
    as are long analysis tables), scenes, software.
    """
    out = Path(out_dir)
    figures = _make_figures(summary, out)
    counts, outcomes = summary["counts"], summary["outcomes"]
    h = html.escape
    analyses = summary.get("analyses") or []
    trust = [a for a in analyses if a.get("kind") == "trust"]
    others = [a for a in analyses if a.get("kind") != "trust"]
    flagged_rows = sum(1 for a in others for r in a.get("rows", []) if r.get("flag"))
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>edem verify {h(summary['campaign'])}</title>",
        f"<style>{CSS}</style></head><body>",
        f"<h1>Campaign <code>{h(summary['campaign'])}</code></h1>",
    ]
    for result in trust:
        parts += _trust_html(result, figures)
    parts += [
        f"<p>{h(summary['description'])}</p>",
        f'<p id="verdict-counts"><b>{len(summary["cases"])} cases: {h(headline(counts))}</b>'
        + (f"; {flagged_rows} comparison row(s) flagged in the analyses below" if flagged_rows else "")
        + f". Outcomes: {outcomes['converges']} converge, {outcomes['refused']} refused.</p>",
        '<table class="legend"><tr><th>verdict</th><th>cases</th><th>meaning</th></tr>'
        + "".join(
            f'<tr><td style="color:{STATUS_COLOURS[v]}"><b>{h(v)}</b></td><td class="num verdict-count" data-verdict="{h(v)}">{counts.get(v, 0)}</td><td>{h(VERDICT_MEANINGS[v])}</td></tr>'
            for v in CASE_VERDICTS
        )
        + "</table>",
        "<p>"
        + f"Finished {h(summary['finished_at'])}; this run took {summary['wall_time_s']:.1f} s ({summary['computed']} cases computed, {summary['cached']} from the cache). "
        + f"Case wall times are those of the run that computed each case (a cached case keeps its own): they add up to {summary['cases_wall_time_s']:.1f} s. "
        + "An FE run shared by several cases (the same FE inputs) counts in the case that computed it; the cases that reused it show its time beside the side, marked reused. "
        + (f"Dask scheduler {h(str(summary['scheduler']))}." if summary.get("scheduler") else f"{summary.get('jobs')} worker process(es).")
        + ' Campaign data: <a href="metrics.json">metrics.json</a>.</p>',
    ]
    shown_in_trust = {name for r in trust for name in r.get("values", {}).get("figures", [])}
    parts.append("<h2>Figures</h2>")
    for fig in (f for f in figures if f.get("name") not in shown_in_trust):
        if fig.get("unavailable"):
            parts.append(f"<p><b>{h(fig['title'])}</b>: {h(fig['error'])}</p>")
        elif fig["error"]:
            parts.append(f"<p><b>{h(fig['title'])}</b>: not drawn ({h(fig['error'])})</p>")
        else:
            parts.append(f'<figure><img src="{h(fig["file"])}" alt="{h(fig["title"])}"><figcaption>{h(fig["title"])}</figcaption></figure>')
    parts += _analyses_html(others)
    parts.append("<h2>Cases</h2>")
    cases = ["<table><tr><th>case</th><th>sides (a vs reference b)</th><th>verdict</th><th>outcome (declared)</th>"
             "<th>metrics (value vs tolerance, and why)</th><th>wall time (s)</th><th>results</th></tr>"]
    for row in summary["cases"]:
        declared = f" ({h(row['expected_outcome'])})" if row.get("expected_outcome") else ""
        side_times = ", ".join(f"{h(s['side'])} {s['wall_time_s']:.3g}" + (" (shared run, reused)" if s.get("reused") else "") for s in row["sides"])
        cases.append(
            "<tr>"
            f"<td><b>{h(row['name'])}</b><br><span class=\"small\">{h(row['description'])}</span></td>"
            f"<td>{h(' vs '.join(s['side'] for s in row['sides']))}</td>"
            + _status_cell(row["status"])
            + f"<td>{h(row['outcome'])}{declared}</td>"
            + _metrics_cell(row)
            + f"<td class=\"num\">{row['wall_time_s']:.3g}{' (cached)' if row['cached'] else ''}<br><span class=\"small\">{side_times}</span></td>"
            + _links_cell(row)
            + "</tr>"
        )
    cases.append("</table>")
    parts += _folded(cases, len(summary["cases"]), "every case with its metrics, verdicts and results")

    parts.append("<h2>Scenes</h2><table><tr><th>scene</th><th>description</th><th>cases (overrides)</th></tr>")
    scenes: dict[str, list[dict[str, Any]]] = {}
    for row in summary["cases"]:
        scenes.setdefault(row["scene"], []).append(row)
    for scene, rows in scenes.items():
        shown = rows if len(rows) <= 12 else rows[:6]
        uses = "<br>".join(
            f"{h(r['name'])}" + (f": <code>{h(_overrides_text(r['overrides']))}</code>" if r["overrides"] else "") for r in shown
        )
        if len(shown) < len(rows):
            uses += f"<br>... and {len(rows) - len(shown)} more cases (see the cases table)"
        parts.append(f"<tr><td><code>{h(scene)}</code></td><td>{h(rows[0]['scene_description'])}</td><td class=\"small\">{uses}</td></tr>")
    parts.append("</table>")

    parts.append("<h2>Software</h2><table>")
    for name, version in summary["versions"].items():
        parts.append(f"<tr><th>{h(name)}</th><td>{h(str(version))}</td></tr>")
    parts.append("</table></body></html>")
    path = out / "report.html"
    path.write_text("\n".join(parts) + "\n", encoding="utf-8")
    return path


def _overrides_text(overrides: dict[str, Any]) -> str:
    text = []
    for key, value in overrides.items():
        shown = json.dumps(value)
        if len(shown) > 80:
            shown = shown[:77] + "..."
        text.append(f"{key}={shown}")
    return "; ".join(text)
