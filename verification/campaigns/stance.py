"""``stance``: EDEM vs DEM over the built-in stance scenes (docs/references.md#the-thesiss-figures, thesis 4.3.4), the thesis's
figures beside ours, DEM vs the FE slab at five instants ("unavailable" without
``fem_reference.run_scene``). Every case names the thesis's ankle in its overrides (its geometry
without cartilage and its threshold law: :data:`verification.campaign_model.THESIS_ANKLE`), the
EDEM-vs-DEM cases, whose figures are set beside the thesis's, its bed too (independent springs),
whatever the scenes' default (the gap law on both layers, coupled)."""

from __future__ import annotations

import tomllib
from typing import Any

import numpy as np

from edem.scene import resolve_scene_path
from verification.campaign_model import THESIS_ANKLE, THESIS_BED, VALUES_AT_REFERENCE_TIMES, Analysis, Campaign, Case, Expect, Figure
from verification.metrics import COMPARISON_METRICS
from verification.verdicts import INVARIANT, MODEL_BAND_REL, Basis

#: wall time with 2 jobs on 2 cores, nothing cached (reported by a user on this machine: about 20 min, two 65-point stances and ten FE instants)
EXPECTED_TIME_S = 1200.0


STANCE_SCENES = ("ideal-stance", "subject-stance")
#: the instants of the pressure maps (and of the FE solves): label, % of stance or "peak-load"
STANCE_INSTANTS = (("heel strike", "0%"), ("foot flat", "13%"), ("mid-stance", "50%"), ("peak load", "peak-load"), ("toe off", "100%"))
STANCE_SERIES = tuple(f"{side}_{name}" for side in "ab" for name in ("peak_pressure_mpa", "mean_contact_area_mm2", "max_superior_displacement_mm", "max_superior_displacement_percent"))
#: docs/references.md#the-thesiss-figures: the thesis's EDEM stance (4.3.4), for qualitative comparison
THESIS_STANCE = {"superior_displacement_mm": 0.57, "superior_displacement_percent": 80.0, "mean_area_edem_cm2": 4.67, "mean_area_dem_cm2": 4.18, "peak_edem_mpa": 7.3, "peak_dem_mpa": 6.92}
THESIS_FLAG_REL = MODEL_BAND_REL  # flag ours against the thesis's beyond the declared model band


def instant_indices(time_s: Any, force_n: Any, instants: tuple[tuple[str, str], ...] = STANCE_INSTANTS) -> list[int]:
    """Time-point index of each instant: the nearest to "<p>%" of the time span, or the largest |F| ("peak-load")."""
    time = np.asarray(time_s, dtype=float)
    force = np.asarray(force_n, dtype=float).reshape(len(time), -1)
    out = []
    for label, where in instants:
        if where == "peak-load":
            out.append(int(np.argmax(np.linalg.norm(force, axis=1))))
        elif where.endswith("%"):
            target = time[0] + float(where[:-1]) / 100.0 * (time[-1] - time[0])
            out.append(int(np.argmin(np.abs(time - target))))
        else:
            raise ValueError(f"instant {label!r}: {where!r} is neither '<p>%' nor 'peak-load'")
    return out


def scene_instants(scene: str, instants: tuple[tuple[str, str], ...] = STANCE_INSTANTS) -> list[int]:
    """instant_indices of a scene's [load] time series, read from its TOML (no geometry is built)."""
    load = tomllib.loads(resolve_scene_path(scene).read_text(encoding="utf-8"))["load"]
    return instant_indices(load["time_s"], load["force_n"], instants)


def _slug(text: str) -> str:
    return "-".join(text.lower().split())


FE_INSTANT_METRICS = COMPARISON_METRICS + VALUES_AT_REFERENCE_TIMES


def fe_instant_case_name(scene: str, label: str) -> str:
    return f"{scene}-fe-{_slug(label)}"


def _stance_cases() -> list[Case]:
    cases = []
    for scene in STANCE_SCENES:
        cases.append(
            Case(
                f"{scene}-edem-vs-dem",
                f"{scene}: EDEM (incremental, push-back) against DEM (each time point static), 65 time points, the thesis's ankle, law and bed (its geometry "
                "without cartilage, the threshold law, independent springs: named in the overrides, the scene's default being the gap law on both layers, coupled) "
                "as the thesis's figures are compared; no tolerance: the methods differ by design",
                scene,
                ("edem", "dem"),
                COMPARISON_METRICS + STANCE_SERIES + ("outcome_mismatch",),
                {"outcome_mismatch": 0.0},  # EDEM must solve the whole stance
                overrides={**THESIS_BED, **THESIS_ANKLE},
                expect=Expect("converges"),
                basis={"outcome_mismatch": Basis(INVARIANT, "the run must solve every time point: a requirement, not an accuracy claim")},
            )
        )
    # The FE slab at each instant of the maps, one case each (a refused instant does not take the
    # others with it; the instants run in parallel). DEM is its like-for-like: both static at the
    # instant, displacement of G from the initial pose of that time point (fem_reference.scene_run).
    for scene in STANCE_SCENES:
        steps = scene_instants(scene)
        overrides = stance_fe_overrides(scene)
        for (label, where), step in zip(STANCE_INSTANTS, steps):
            cases.append(
                Case(
                    fe_instant_case_name(scene, label),
                    f"{scene} at {label} ({where}, step {step}): DEM against the FE slab, both static at that time point, "
                    f"both without ligaments{' and with ' + ', '.join(STANCE_FE_FIXED.get(scene, ())) + ' fixed' if scene in STANCE_FE_FIXED else ''}; no tolerance (reported)",
                    scene,
                    ("dem", "fe-slab"),
                    FE_INSTANT_METRICS,
                    overrides=overrides,
                    options={"steps": [step]},
                    params={"step": float(step)},
                )
            )
    return cases


#: DOFs fixed (in both DEM and FE) where the frictionless FE slab cannot resist them: on the ideal
#: ankle (a cylinder under a plane) every contact normal is perpendicular to the antero-posterior
#: slide once the tibia turns, and fem_reference refuses those instants (the discrete springs along
#: M's normals resist it; the constraint carries that load component instead).
STANCE_FE_FIXED = {"ideal-stance": ("ty",)}


def stance_fe_overrides(scene: str) -> dict[str, Any]:
    """Overrides of the DEM-vs-FE cases: the thesis's ankle (the threshold law, the FE slab's twin),
    no ligaments (the FE models none), STANCE_FE_FIXED added to the scene's own fixed DOFs."""
    overrides: dict[str, Any] = {"ligaments": [], **THESIS_ANKLE}
    if scene in STANCE_FE_FIXED:
        data = tomllib.loads(resolve_scene_path(scene).read_text(encoding="utf-8"))
        fixed = list(data.get("constraints", {}).get("fixed_dofs", []))
        overrides["constraints.fixed_dofs"] = fixed + [d for d in STANCE_FE_FIXED[scene] if d not in fixed]
    return overrides


def _stance_figures() -> tuple[Figure, ...]:
    figures = []
    for scene in STANCE_SCENES:
        case = f"{scene}-edem-vs-dem"
        for column, what in (("disp_z_mm", "talus (G) superior displacement"), ("peak_pressure_mpa", "peak pressure"), ("contact_area_mm2", "contact area")):
            figures.append(Figure(f"{scene}-{column}", f"{scene}: {what} over the stance, EDEM and DEM", "timeseries", (case,), column=column))
        figures.append(Figure(f"{scene}-maps", f"{scene}: pressure maps, EDEM vs DEM", "maps", (case,), instants=STANCE_INSTANTS))
    for scene in STANCE_SCENES:
        for instant in STANCE_INSTANTS:
            name = fe_instant_case_name(scene, instant[0])
            figures.append(Figure(name + "-maps", f"{scene}: pressure maps, DEM vs FE slab", "maps", (name,), instants=(instant,)))
    return tuple(figures)


def _stance_analyses() -> tuple[Analysis, ...]:
    t = THESIS_STANCE
    rows = []
    for scene in STANCE_SCENES:
        case = f"{scene}-edem-vs-dem"
        rows += [
            {"scene": scene, "quantity": "talus max superior displacement (mm)", "method": "EDEM", "case": case, "metric": "a_max_superior_displacement_mm", "thesis": t["superior_displacement_mm"]},
            {"scene": scene, "quantity": "  ... at % stance", "method": "EDEM", "case": case, "metric": "a_max_superior_displacement_percent", "thesis": t["superior_displacement_percent"]},
            {"scene": scene, "quantity": "talus max superior displacement (mm)", "method": "DEM", "case": case, "metric": "b_max_superior_displacement_mm", "thesis": None},
            {"scene": scene, "quantity": "  ... at % stance", "method": "DEM", "case": case, "metric": "b_max_superior_displacement_percent", "thesis": None},
            {"scene": scene, "quantity": "mean contact area (cm^2)", "method": "EDEM", "case": case, "metric": "a_mean_contact_area_mm2", "scale": 0.01, "thesis": t["mean_area_edem_cm2"]},
            {"scene": scene, "quantity": "mean contact area (cm^2)", "method": "DEM", "case": case, "metric": "b_mean_contact_area_mm2", "scale": 0.01, "thesis": t["mean_area_dem_cm2"]},
            {"scene": scene, "quantity": "peak pressure over the stance (MPa)", "method": "EDEM", "case": case, "metric": "a_peak_pressure_mpa", "thesis": t["peak_edem_mpa"]},
            {"scene": scene, "quantity": "peak pressure over the stance (MPa)", "method": "DEM", "case": case, "metric": "b_peak_pressure_mpa", "thesis": t["peak_dem_mpa"]},
        ]
    fe_cases = tuple(fe_instant_case_name(scene, label) for scene in STANCE_SCENES for label, _ in STANCE_INSTANTS)
    columns = [
        {"header": "DEM regularised peak (MPa)", "metric": "a_at_b_regularised_peak_pressure_mpa"},
        {"header": "FE regularised peak (MPa)", "metric": "b_regularised_peak_pressure_mpa"},
        {"header": "regularised peak rel. error", "metric": "regularised_peak_pressure_rel_error"},
        {"header": "DEM area (cm^2)", "metric": "a_at_b_mean_contact_area_mm2", "scale": 0.01},
        {"header": "FE area (cm^2)", "metric": "b_mean_contact_area_mm2", "scale": 0.01},
        {"header": "area rel. error", "metric": "contact_area_rel_error"},
        {"header": "DEM |u| (mm)", "metric": "a_at_b_displacement_norm_mm"},
        {"header": "FE |u| (mm)", "metric": "b_displacement_norm_mm"},
        {"header": "displacement rel. error", "metric": "displacement_rel_error"},
        {"header": "pressure L2 rel. error", "metric": "pressure_l2_rel_error"},
    ]
    return (
        Analysis(
            "thesis-stance",
            "Stance: our runs beside the thesis's figures (docs/references.md#the-thesiss-figures; thesis EDEM stance 4.3.4). Reported, no verdict; flagged beyond +-25 %",
            "thesis",
            tuple(dict.fromkeys(r["case"] for r in rows)),
            {"rows": rows, "flag_rel": THESIS_FLAG_REL},
        ),
        Analysis(
            "fe-instants",
            "DEM against the FE slab at the five instants (both static, both without ligaments; ideal stance with ty fixed in both). Reported, no verdict",
            "table",
            fe_cases,
            {"columns": columns},
        ),
    )


def campaign() -> Campaign:
    return Campaign(
        "stance",
        "EDEM vs DEM over the built-in ideal and subject stances (65 time points): displacement, peak pressure and contact area over time, pressure maps at five instants, "
        "the thesis's figures beside ours, and the FE slab at those instants when fem_reference.run_scene exists.",
        tuple(_stance_cases()),
        _stance_figures(),
        _stance_analyses(),
    )
