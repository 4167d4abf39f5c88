"""EDEM/DEM against the FE reference on the ankle scenes (issue 5): three campaigns as data.

* ``cylinder-plane``: the independent-spring bed against the continuum on the idealised ankle,
  one-at-a-time sweeps around a base case: load (100, 333, 1000, 4190 N) and Poisson's ratio
  (0, 0.3, 0.42, 0.45, 0.49, 0.499) on ``ideal-standing`` (threshold law, DEM) vs the FE slab and
  on ``cylinder-layer`` (gap law, DEM) vs the FE layer, and the cartilage thickness (1, 2, 3 mm:
  ``geometry.plafond_gap_mm`` and ``cartilage.thickness_mm`` together) on ``cylinder-layer``.
  FE: P2 at 1.0 mm (Taylor-Hood automatically from nu = 0.49). Generous tolerances: the campaign
  measures; it fails only when something is broken (NaN, a force residual, absurd errors).
* ``subject``: standing and toe-off on the subject-like ankle, DEM and EDEM vs the FE slab (P2,
  1.0 mm), without ligaments (the FE models none), toe-off with ``ty`` fixed on both sides (its
  load has an antero-posterior component the frictionless FE cannot resist otherwise).
* ``error-vs-runtime``: error against wall time of both sides on ideal standing (333 N, no
  ligaments): DEM over the ideal ankle's mesh size, the FE slab over P1 mesh sizes (both against
  the FE slab P2 at 1.0 mm: the truth, side ``fe-slab-truth``), and EDEM over the step count of a
  0 -> 333 N ramp (against EDEM at 128 steps: side ``edem-128-steps``). Figure: error vs side a's
  wall time on log axes; analysis: the Pareto front per truth (points no other beats in both error and time).

This module also registers what those campaigns need beyond the existing registries: the two
truth sides (in :data:`verification.sides.SIDES`) and the ``pareto`` analysis kind (in
:data:`verification.analyses.ANALYSES`). It is imported by :mod:`verification.campaigns`, so
spawned campaign workers see them too.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from verification import analyses as _analyses
from verification import sides as _sides
from verification.campaigns import Analysis, Campaign, Case, Figure, ramp_overrides
from verification.metrics import SPEC8_METRICS

# ---------------------------------------------------------------------------------------------
# Truth sides: fixed settings whatever the case's options (and geometry mesh) say

TRUTH_FE = {"mesh_size_mm": 1.0, "degree": 2}  # the FE slab, P2 at 1.0 mm (71 k DOFs on the ideal ankle)
TRUTH_STEPS = 128


def _run_fe_truth(scene_ref: str, overrides: dict[str, Any], out_dir: Path, options: dict[str, Any]) -> str:
    """The FE slab at TRUTH_FE on the scene's own geometry mesh (a geometry.mesh_size_mm override
    of the case, which sweeps the springs, is dropped), ignoring the case's options."""
    kept = {k: v for k, v in overrides.items() if k != "geometry.mesh_size_mm"}
    return _sides._run_fe("slab")(scene_ref, kept, out_dir, dict(TRUTH_FE))


def resample_load(overrides: dict[str, Any], n_steps: int) -> dict[str, Any]:
    """The overrides with the load history load.time_s / load.force_n linearly re-sampled at
    n_steps equal increments of the same time span."""
    import numpy as np

    times = np.asarray(overrides["load.time_s"], dtype=float)
    forces = np.asarray(overrides["load.force_n"], dtype=float).reshape(len(times), 3)
    new_t = np.linspace(times[0], times[-1], n_steps + 1)
    new_f = np.stack([np.interp(new_t, times, forces[:, j]) for j in range(3)], axis=1)
    return {**overrides, "load.time_s": new_t.tolist(), "load.force_n": new_f.tolist()}


def _run_edem_truth(scene_ref: str, overrides: dict[str, Any], out_dir: Path, options: dict[str, Any]) -> str:
    """EDEM over the case's load history (load.time_s / load.force_n overrides) re-sampled at
    TRUTH_STEPS equal increments."""
    if "load.time_s" not in overrides or "load.force_n" not in overrides:
        from edem.errors import InputError

        raise InputError("the edem-128-steps side needs a load history", key="overrides", expected="load.time_s and load.force_n overrides")
    return _sides._run_discrete("edem")(scene_ref, resample_load(overrides, TRUTH_STEPS), out_dir, options)


_sides.SIDES.setdefault("fe-slab-truth", _run_fe_truth)
_sides.SIDES.setdefault("edem-128-steps", _run_edem_truth)


# ---------------------------------------------------------------------------------------------
# The pareto analysis kind


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
        if row is None or row["status"] in ("unavailable", "error") or not row.get("sides"):
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
        return {"columns": [], "rows": [], "status": _analyses.UNAVAILABLE, "notes": ["no case has a value"], "values": {}}
    # a front per truth (errors against different truths are not comparable)
    for truth in dict.fromkeys(e["truth"] for e in entries):
        group = [e for e in entries if e["truth"] == truth]
        for entry, on in zip(group, pareto_front([(e["time_s"], e["error"]) for e in group])):
            entry["front"] = on
    entries.sort(key=lambda e: e["time_s"])
    entries.sort(key=lambda e: (e["truth"], e["time_s"]))
    out_rows = [{"cells": [e["case"], e["family"], e["truth"], _analyses._fmt(e["time_s"], 3), _analyses._fmt(e["error"], 3), "front" if e["front"] else ""], "flag": False} for e in entries]
    truths = {}
    for e in entries:
        if e["truth_time_s"] is not None:
            truths.setdefault(e["family"], []).append(e["truth_time_s"])
    notes = [analysis.settings.get("truth", "")] + [f"{fam}: its truth took {min(ts):.3g} .. {max(ts):.3g} s per run" for fam, ts in truths.items()]
    notes.append("Wall time of side a as run by the campaign (2 jobs sharing 2 cores: contention included); front = no other point against the same truth is both faster and more accurate (one front per truth: errors against different truths do not compare).")
    return {
        "columns": ["case", "family", "against", "wall time a (s)", metric, "Pareto"],
        "rows": out_rows,
        "status": _analyses.REPORTED,
        "notes": [n for n in notes if n],
        "values": {"points": entries, "front": [e["case"] for e in entries if e["front"]]},
    }


_analyses.ANALYSES.setdefault("pareto", pareto_analysis)


# ---------------------------------------------------------------------------------------------
# cylinder-plane

FE_COARSE = {"mesh_size_mm": 1.0, "degree": 2}  # P2 at 1.0 mm; Taylor-Hood (auto) from nu = 0.49
SWEEP_LOADS_N = (100.0, 333.0, 1000.0, 4190.0)
SWEEP_NUS = (0.0, 0.3, 0.42, 0.45, 0.49, 0.499)
SWEEP_THICKNESS_MM = (1.0, 2.0, 3.0)
BASE = {"load": 333.0, "nu": 0.42, "thickness": 2.0}
VALUE_METRICS = (
    "a_at_b_peak_pressure_mpa",
    "b_peak_pressure_mpa",
    "a_at_b_mean_contact_area_mm2",
    "b_mean_contact_area_mm2",
    "a_at_b_displacement_norm_mm",
    "b_displacement_norm_mm",
)
CHECK_METRICS = ("force_residual_rel", "non_finite_outputs")
FE_COMPARE_METRICS = SPEC8_METRICS + VALUE_METRICS + CHECK_METRICS
#: generous: a relative error beyond 10 (1000 %) or a NaN means something is broken, not a model gap
FE_COMPARE_TOL = {**{m: 10.0 for m in SPEC8_METRICS}, "force_residual_rel": 1e-6, "non_finite_outputs": 0.0}
ERROR_PANELS = ("peak_pressure_rel_error", "contact_area_rel_error", "displacement_rel_error", "pressure_l2_rel_error")
#: the two models of the ideal ankle: (prefix, scene, sides, what)
CP_MODELS = (
    ("slab", "ideal-standing", ("dem", "fe-slab"), "ideal ankle (R 20 mm, 114 deg, plafond 1.5 mm above), threshold-law DEM vs the FE slab"),
    ("layer", "cylinder-layer", ("dem", "fe-layer"), "cylinder with a bonded layer on a plane, gap-law DEM vs the FE layer"),
)


def _cp_name(model: str, load: float, nu: float, thickness: float) -> str:
    return f"{model}-F{load:g}-nu{nu:g}" + (f"-t{thickness:g}" if model == "layer" else "")


def _cp_cases() -> list[Case]:
    points: list[tuple[str, float, float, float]] = []
    for model, *_ in CP_MODELS:
        grid = [(f, BASE["nu"], BASE["thickness"]) for f in SWEEP_LOADS_N] + [(BASE["load"], nu, BASE["thickness"]) for nu in SWEEP_NUS]
        if model == "layer":
            grid += [(BASE["load"], BASE["nu"], t) for t in SWEEP_THICKNESS_MM]
        for p in dict.fromkeys(grid):
            points.append((model, *p))
    info = {m: (scene, sides, what) for m, scene, sides, what in CP_MODELS}
    cases = []
    for model, load, nu, thickness in points:
        scene, sides, what = info[model]
        overrides: dict[str, Any] = {"load.force_n": [0.0, 0.0, load], "cartilage.poissons_ratio": nu}
        if model == "slab":
            overrides["ligaments"] = []  # the FE models none (slack at the neutral pose anyway)
        else:
            overrides.update({"geometry.plafond_gap_mm": thickness, "cartilage.thickness_mm": thickness})
        element = "Taylor-Hood P2-P1" if nu >= 0.49 else "P2"
        cases.append(
            Case(
                _cp_name(model, load, nu, thickness),
                f"{what}: {load:g} N, nu {nu:g}" + (f", layer {thickness:g} mm (plane touching it)" if model == "layer" else ", no ligaments")
                + f"; FE {element} at 1.0 mm. Generous tolerances (measured, not judged)",
                scene,
                sides,
                FE_COMPARE_METRICS,
                dict(FE_COMPARE_TOL),
                overrides=overrides,
                options=dict(FE_COARSE),
                params={"load_n": load, "poissons_ratio": nu, "thickness_mm": thickness},
                maps=(load, nu, thickness) == (BASE["load"], BASE["nu"], BASE["thickness"]),
            )
        )
    return cases


def _cp_sweeps() -> list[tuple[str, str, str, tuple[str, ...], bool]]:
    """(figure name, title, x param, cases, logx) of each one-at-a-time sweep."""
    b = BASE
    out = []
    for model, _scene, _sides, what in CP_MODELS:
        out.append((f"{model}-load", f"{what}: DEM errors against the FE vs load (nu {b['nu']:g})", "load_n",
                    tuple(_cp_name(model, f, b["nu"], b["thickness"]) for f in SWEEP_LOADS_N), True))
        out.append((f"{model}-poisson", f"{what}: DEM errors against the FE vs Poisson's ratio ({b['load']:g} N)", "poissons_ratio",
                    tuple(_cp_name(model, b["load"], nu, b["thickness"]) for nu in SWEEP_NUS), False))
    out.append(("layer-thickness", "Cylinder with a layer: DEM (gap law) errors against the FE layer vs the layer thickness (333 N, nu 0.42)", "thickness_mm",
                tuple(_cp_name("layer", b["load"], b["nu"], t) for t in SWEEP_THICKNESS_MM), False))
    return out


def cylinder_plane_campaign() -> Campaign:
    cases = tuple(_cp_cases())
    sweeps = _cp_sweeps()
    figures = tuple(Figure(name, title, "sweep", names, x=x, y=ERROR_PANELS, logx=logx, logy=True) for name, title, x, names, logx in sweeps)
    columns = [
        {"header": "DEM peak (MPa)", "metric": "a_at_b_peak_pressure_mpa"},
        {"header": "FE peak (MPa)", "metric": "b_peak_pressure_mpa"},
        {"header": "peak err", "metric": "peak_pressure_rel_error"},
        {"header": "DEM area (mm^2)", "metric": "a_at_b_mean_contact_area_mm2"},
        {"header": "FE area (mm^2)", "metric": "b_mean_contact_area_mm2"},
        {"header": "area err", "metric": "contact_area_rel_error"},
        {"header": "DEM |u| (mm)", "metric": "a_at_b_displacement_norm_mm"},
        {"header": "FE |u| (mm)", "metric": "b_displacement_norm_mm"},
        {"header": "disp err", "metric": "displacement_rel_error"},
        {"header": "L2 err", "metric": "pressure_l2_rel_error"},
    ]
    analyses = tuple(
        Analysis(f"{name}-table", f"{title}. Reported, no verdict", "table", names, {"columns": columns}) for name, title, _x, names, _l in sweeps
    )
    return Campaign(
        "cylinder-plane",
        "EDEM/DEM (independent springs) vs the FE continuum on the idealised ankle: one-at-a-time sweeps of load, Poisson's ratio (threshold law vs FE slab; gap law vs FE layer) "
        "and layer thickness (gap law vs FE layer) around 333 N, nu 0.42, 2 mm. FE P2 at 1.0 mm (Taylor-Hood from nu 0.49). Where the errors grow, the independent-spring "
        "assumption breaks (high nu: the continuum's lateral coupling; thin layers and high loads: the contact edge).",
        cases,
        figures,
        analyses,
    )


# ---------------------------------------------------------------------------------------------
# subject

SUBJECT_SCENES = (
    ("subject-standing", {"ligaments": []}, "333 N vertical at 0 deg; scene constraints (tx, rx, ry, rz fixed)"),
    ("subject-toe-off", {"ligaments": [], "constraints.fixed_dofs": ["tx", "ty", "rx", "ry", "rz"]}, "4190 N at 16.31 deg; ty fixed on both sides too (the load's antero-posterior component: the frictionless FE cannot resist it)"),
)


def subject_campaign() -> Campaign:
    cases = []
    for scene, overrides, what in SUBJECT_SCENES:
        for method in ("dem", "edem"):
            cases.append(
                Case(
                    f"{scene}-{method}-vs-fe",
                    f"{scene}: {method.upper()} vs the FE slab (P2, 1.0 mm), {what}; ligaments removed from the discrete side (the FE models none). Generous tolerances",
                    scene,
                    (method, "fe-slab"),
                    FE_COMPARE_METRICS,
                    dict(FE_COMPARE_TOL),
                    overrides=dict(overrides),
                    options=dict(FE_COARSE),
                    maps=method == "dem",
                )
            )
    columns = [
        {"header": "discrete peak (MPa)", "metric": "a_at_b_peak_pressure_mpa"},
        {"header": "FE peak (MPa)", "metric": "b_peak_pressure_mpa"},
        {"header": "peak err", "metric": "peak_pressure_rel_error"},
        {"header": "mean p err", "metric": "mean_pressure_rel_error"},
        {"header": "discrete area (cm^2)", "metric": "a_at_b_mean_contact_area_mm2", "scale": 0.01},
        {"header": "FE area (cm^2)", "metric": "b_mean_contact_area_mm2", "scale": 0.01},
        {"header": "area err", "metric": "contact_area_rel_error"},
        {"header": "discrete |u| (mm)", "metric": "a_at_b_displacement_norm_mm"},
        {"header": "FE |u| (mm)", "metric": "b_displacement_norm_mm"},
        {"header": "disp err", "metric": "displacement_rel_error"},
        {"header": "L2 err", "metric": "pressure_l2_rel_error"},
    ]
    names = tuple(c.name for c in cases)
    return Campaign(
        "subject",
        "Standing and toe-off on the subject-like ankle: DEM and EDEM (no ligaments) vs the FE slab (P2, 1.0 mm); toe-off with ty fixed on both sides.",
        tuple(cases),
        (),
        (Analysis("subject-metrics", "Subject-like ankle: discrete vs FE slab (SPEC 8 metrics). Reported, no verdict", "table", names, {"columns": columns}),),
    )


# ---------------------------------------------------------------------------------------------
# error-vs-runtime

ERT_SCENE = "ideal-standing"
ERT_LOAD_N = 333.0
ERT_DEM_SIZES_MM = (2.0, 1.4, 0.94, 0.66, 0.47, 0.33)
ERT_FE_P1_SIZES_MM = (1.0, 0.7, 0.5)
ERT_STEPS = (8, 16, 32, 64)
ERT_METRICS = ("pressure_l2_rel_error", "peak_pressure_rel_error", "displacement_rel_error")
ERT_TRUTH_NOTE = (
    "Truth: DEM and FE P1 points against the FE slab P2 at 1.0 mm (side fe-slab-truth; within 0.7 % of P2 at 0.7 mm, fem_reference.scene_run); "
    "EDEM step counts against EDEM at 128 steps (side edem-128-steps). DEM errors level off at the model gap (independent springs vs continuum), not at zero."
)


def _ert_cases() -> list[Case]:
    base = {"ligaments": []}
    cases = []
    for size in ERT_DEM_SIZES_MM:
        cases.append(
            Case(
                f"dem-{size:g}",
                f"DEM, ideal standing 333 N without ligaments, springs on a {size:g} mm mesh, vs the FE slab P2 at 1.0 mm (the truth)",
                ERT_SCENE,
                ("dem", "fe-slab-truth"),
                ERT_METRICS + CHECK_METRICS,
                {**{m: 10.0 for m in ERT_METRICS}, "force_residual_rel": 1e-6, "non_finite_outputs": 0.0},
                overrides={**base, "geometry.mesh_size_mm": size},
                params={"mesh_size_mm": size},
            )
        )
    for size in ERT_FE_P1_SIZES_MM:
        cases.append(
            Case(
                f"fe-p1-{size:g}",
                f"FE slab P1 at {size:g} mm, ideal standing 333 N, vs the FE slab P2 at 1.0 mm (the truth)",
                ERT_SCENE,
                ("fe-slab", "fe-slab-truth"),
                ERT_METRICS + ("non_finite_outputs",),
                {**{m: 10.0 for m in ERT_METRICS}, "non_finite_outputs": 0.0},
                overrides=dict(base),
                options={"mesh_size_mm": size, "degree": 1},
                params={"mesh_size_mm": size},
            )
        )
    for n in ERT_STEPS:
        cases.append(
            Case(
                f"edem-{n}",
                f"EDEM, ideal standing without ligaments, ramp 0 -> 333 N in {n} increments, vs the same ramp in {TRUTH_STEPS} (the truth; compared at the last time point)",
                ERT_SCENE,
                ("edem", "edem-128-steps"),
                ERT_METRICS + CHECK_METRICS,
                {**{m: 10.0 for m in ERT_METRICS}, "force_residual_rel": 1e-6, "non_finite_outputs": 0.0},
                overrides={**base, **ramp_overrides(n, ERT_LOAD_N)},
                params={"steps": n},
            )
        )
    return cases


def error_vs_runtime_campaign() -> Campaign:
    cases = tuple(_ert_cases())
    names = tuple(c.name for c in cases)
    return Campaign(
        "error-vs-runtime",
        "Error against wall time on ideal standing (333 N, no ligaments): DEM over the spring mesh (2.0 .. 0.33 mm) and FE P1 (1.0, 0.7, 0.5 mm) against the FE slab P2 at 1.0 mm; "
        "EDEM over 8 .. 64 ramp increments against 128. P2 at 0.7 mm (8 min, 8 GB) is left out. Log-log figure and the Pareto front.",
        cases,
        (
            Figure("error-vs-time", "Error against wall time of side a (log-log); families: dem (mesh), fe-p1 (mesh), edem (steps); dashed: Pareto front per truth (fe-slab-truth, edem-128-steps)", "error-vs-time", names, y=ERT_METRICS, logx=True, logy=True),
            Figure("dem-mesh", "DEM against the FE truth vs the spring mesh size", "sweep", tuple(f"dem-{s:g}" for s in ERT_DEM_SIZES_MM), x="mesh_size_mm", y=ERT_METRICS, logx=True, logy=True),
            Figure("edem-steps", "EDEM against 128 steps vs the step count (dotted: slope -1)", "sweep", tuple(f"edem-{n}" for n in ERT_STEPS), x="steps", y=ERT_METRICS, logx=True, logy=True, reference_slope=-1.0),
        ),
        tuple(
            Analysis(f"pareto-{m}", f"Pareto front of {m} against wall time", "pareto", names, {"metric": m, "truth": ERT_TRUTH_NOTE}) for m in ("pressure_l2_rel_error", "displacement_rel_error")
        ),
    )


def fe_campaigns() -> dict[str, Campaign]:
    return {c.name: c for c in (cylinder_plane_campaign(), subject_campaign(), error_vs_runtime_campaign())}
