"""``thin-layer``: the coupled thin-layer bed (``cartilage.coupling = "thin-layer"``) and the
independent springs against the FE continuum, on the bonded cylinder layer (``cylinder-layer``,
gap law, DEM vs the FE layer), the ideal ankle (``ideal-standing``, threshold law, DEM vs the FE
slab, no ligaments) and the subject-like ankle standing (``subject-standing``, threshold law, DEM
vs the FE slab, no ligaments: the FE models none; the scene's constraints). Sweeps: Poisson's
ratio (0, 0.3, 0.42, 0.45, 0.49, 0.499) at each layer thickness (1, 2, 3 mm:
``geometry.plafond_gap_mm`` and ``cartilage.thickness_mm`` together) at 333 N on the cylinder
layer, and at 333 N on both ankles; loads 333, 1000, 4190 N at nu 0.42 and 0.49 (cylinder layer
2 mm; ideal ankle). Every point is three cases, ``<model>-coupled-...`` (the Pade symbol),
``<model>-two-pole-...`` (``cartilage.thin_layer_symbol = "two-pole"``) and ``<model>-springs-...``;
they share one FE run (the FE never reads the coupling: verification.runner's side store).

FE (P2; Taylor-Hood from nu 0.49): the base cylinder layer (2 mm, 333 N, the nu sweep) at
0.7 mm (``FE_LAYER``: M's triangles halved, ceil(2 / 0.7) = 3 elements through the layer), the
finest level of the ``fe-convergence`` study, which gives each of these six runs its own
estimated error (docs/campaigns.md; until 2026-11 this sweep used 0.5 mm with two elements
through the layer, the same triangles and one layer fewer, whose error no study gave); 293k DOFs,
2-3 min per P2 run at 4.4 GB by LU. Every other case stays at 1.0 mm (``FE_COARSE``: the default
layer count there, ceil(t / size): 1, 2, 3 elements through the 1, 2, 3 mm layers), the middle
level of the same study, which gives their errors too (the 1 mm layer's excepted: its 2.0 and
1.0 mm meshes coincide, so it has no three-level estimate and stays "FE error unknown").
The ankles (slab): 30 s to 4 min per run at 1.0 mm.
Tolerances are generous (the campaign measures; it fails only when something is
broken). The issue's goal (displacement, peak and contact area within 10 % of the FE up to nu
0.499 and within 5 % up to 0.42, pressure-field L2 at most half the independent springs') is the
analyses ``goal`` (Pade) and ``goal-two-pole`` (:func:`verification.analyses.goal_analysis`):
each coupled point that misses it is flagged with what it misses, and its notes say where in
sentences; not a failure."""

from __future__ import annotations

from typing import Any

from verification.campaign_model import THESIS_ANKLE, THESIS_BED, Analysis, Campaign, Case, Figure
from verification.fe_comparison import ERROR_PANELS, FE_COARSE, FE_TABLE_COLUMNS, fe_comparison_case

#: the FE layer of the base cylinder sweep: the fe-convergence study's finest level (module docstring)
FE_LAYER = {"mesh_size_mm": 0.7, "degree": 2}

#: wall time with 2 jobs on 2 cores, nothing cached (estimate from measured runs: with every FE
#: layer at 1.0 mm it took 1421 s at load 4-7; the six base-layer runs at 0.5 mm took 1818 s of FE
#: under load 8 instead of 225 s; at 0.7 mm, in fe-convergence, 77-927 s each, 1860 s together, at
#: load 2-4)
EXPECTED_TIME_S = 2000.0

NUS = (0.0, 0.3, 0.42, 0.45, 0.49, 0.499)
THICKNESS_MM = (1.0, 2.0, 3.0)
LOADS_N = (333.0, 1000.0, 4190.0)
LOAD_NUS = (0.42, 0.49)
BASE_LOAD_N, BASE_THICKNESS_MM = 333.0, 2.0
#: name: (overrides, what, the figures' legend); the coupled variants each have their goal analysis against the springs
VARIANTS = {
    "coupled": ({"cartilage.coupling": "thin-layer"}, "coupled thin layer (Pade symbol)", "coupled, Pade"),
    "two-pole": ({"cartilage.coupling": "thin-layer", "cartilage.thin_layer_symbol": "two-pole"}, "coupled thin layer (two-pole symbol)", "coupled, two-pole"),
    "springs": (THESIS_BED, "independent springs", "independent springs"),  # named: the ankle scenes' default is the coupled layer
}
COUPLED_VARIANTS = ("coupled", "two-pole")
#: (model, scene, sides, what)
MODELS = (
    ("layer", "cylinder-layer", ("dem", "fe-layer"), "cylinder (R 20 mm) with a bonded layer on a plane, gap-law DEM vs the FE layer"),
    ("slab", "ideal-standing", ("dem", "fe-slab"), "ideal ankle (R 20 mm, 114 deg, plafond 1.5 mm above), threshold-law DEM vs the FE slab, no ligaments"),
    ("subject", "subject-standing", ("dem", "fe-slab"), "subject-like ankle standing (scene constraints), threshold-law DEM vs the FE slab, no ligaments"),
)
#: the issue's goal for the coupled bed (verification.analyses.goal_analysis)
GOAL = {
    "metrics": ("displacement_rel_error", "regularised_peak_pressure_rel_error", "contact_area_rel_error"),
    "strict": 0.05, "strict_nu": 0.42, "loose": 0.10, "ratio_metric": "pressure_l2_rel_error", "ratio": 0.5,
}
GOAL_LINES = tuple((m, value, text) for m in GOAL["metrics"] for value, text in ((GOAL["strict"], "goal up to nu 0.42 (5 %)"), (GOAL["loose"], "goal up to nu 0.499 (10 %)")))


def case_name(model: str, variant: str, load: float, thickness: float | None, nu: float) -> str:
    """The nu comes last: the error-vs-time figure groups a family by the name up to its last '-'."""
    return f"{model}-{variant}-F{load:g}" + (f"-t{thickness:g}" if thickness is not None else "") + f"-nu{nu:g}"


def _points() -> list[tuple[str, float, float | None, float]]:
    points = []
    for t in sorted(THICKNESS_MM, key=lambda t: t != BASE_THICKNESS_MM):  # the base thickness first
        points += [("layer", BASE_LOAD_N, t, nu) for nu in NUS]
    points += [("layer", f, BASE_THICKNESS_MM, nu) for f in LOADS_N for nu in LOAD_NUS]
    points += [("slab", BASE_LOAD_N, None, nu) for nu in NUS]
    points += [("slab", f, None, nu) for f in LOADS_N for nu in LOAD_NUS]
    points += [("subject", BASE_LOAD_N, None, nu) for nu in NUS]
    return list(dict.fromkeys(points))


def _cases() -> list[Case]:
    info = {m: (scene, sides, what) for m, scene, sides, what in MODELS}
    cases = []
    for model, load, thickness, nu in _points():
        scene, sides, what = info[model]
        overrides: dict[str, Any] = {"load.force_n": [0.0, 0.0, load], "cartilage.poissons_ratio": nu}
        if thickness is None:
            overrides["ligaments"] = []
            overrides.update(THESIS_ANKLE)  # the threshold law on the thesis's geometry: the FE slab's twin
        else:
            overrides.update({"geometry.plafond_gap_mm": thickness, "cartilage.thickness_mm": thickness})
        element = "Taylor-Hood P2-P1" if nu >= 0.49 else "P2"
        fe = FE_LAYER if (model, load, thickness) == ("layer", BASE_LOAD_N, BASE_THICKNESS_MM) else FE_COARSE
        fe_text = f"FE {element} at {fe['mesh_size_mm']:g} mm"
        for variant, (extra, bed, _) in VARIANTS.items():
            cases.append(
                fe_comparison_case(
                    case_name(model, variant, load, thickness, nu),
                    f"{what}; {bed}: {load:g} N, nu {nu:g}"
                    + (f", layer {thickness:g} mm" if thickness is not None else "") + f"; {fe_text}. Measured, not judged",
                    scene,
                    sides,
                    overrides={**overrides, **extra},
                    options=fe,
                    params={"load_n": load, "poissons_ratio": nu, "thickness_mm": thickness or 0.0},
                    maps=(model, load, thickness, nu) in (("layer", BASE_LOAD_N, BASE_THICKNESS_MM, 0.49), ("subject", BASE_LOAD_N, None, 0.49)),
                )
            )
    return cases


def campaign() -> Campaign:
    cases = tuple(_cases())
    names = tuple(c.name for c in cases)
    figures, analyses = [], []
    sweeps = [(f"layer-t{t:g}", f"cylinder layer {t:g} mm, 333 N", "layer", BASE_LOAD_N, t) for t in THICKNESS_MM]
    sweeps.append(("slab", "ideal ankle vs the FE slab, 333 N", "slab", BASE_LOAD_N, None))
    sweeps.append(("subject", "subject-like ankle standing vs the FE slab, 333 N", "subject", BASE_LOAD_N, None))

    def overlay(name: str, title: str, x: str, series: dict[str, tuple[str, ...]]) -> Figure:
        return Figure(name, title, "sweep", tuple(n for group in series.values() for n in group), x=x, y=ERROR_PANELS, logy=True,
                      series=tuple((VARIANTS[variant][2], group) for variant, group in series.items()), lines=GOAL_LINES)

    for tag, what, model, load, t in sweeps:
        series = {variant: tuple(case_name(model, variant, load, t, nu) for nu in NUS) for variant in VARIANTS}
        figures.append(overlay(f"{tag}-poisson", f"{what}: errors against the FE vs Poisson's ratio, the coupled thin layer (Pade and two-pole symbols) and the independent springs (dashed: the goal)",
                               "poissons_ratio", series))
        rows = tuple(n for group in series.values() for n in group)
        analyses.append(Analysis(f"{tag}-table", f"{what}: the coupled beds (Pade, two-pole) and the independent springs against the FE, by Poisson's ratio. Reported, no verdict", "table", rows, {"columns": FE_TABLE_COLUMNS}))
    series = {variant: tuple(case_name("layer", variant, BASE_LOAD_N, t, 0.49) for t in THICKNESS_MM) for variant in VARIANTS}
    figures.append(overlay("layer-thickness", "cylinder layer, 333 N, nu 0.49: errors against the FE layer vs the thickness, the coupled beds (Pade, two-pole) and the independent springs (dashed: the goal)",
                           "thickness_mm", series))
    load_rows = tuple(case_name(m, v, f, BASE_THICKNESS_MM if m == "layer" else None, nu) for m in ("layer", "slab") for v in VARIANTS for nu in LOAD_NUS for f in LOADS_N)
    analyses.append(Analysis("load-table", "Both models over the load (layer 2 mm; ideal ankle), nu 0.42 and 0.49. Reported, no verdict", "table", load_rows, {"columns": FE_TABLE_COLUMNS}))
    figures.append(Figure("error-vs-time", "Error against the DEM wall time, the coupled beds (Pade, two-pole) vs the independent springs (families: model-variant-load-thickness, points by nu); dashed: the Pareto front",
                          "error-vs-time", names, y=("pressure_l2_rel_error", "displacement_rel_error"), logx=True, logy=True))
    analyses += [Analysis(f"pareto-{m}", f"Pareto front of {m} against the DEM wall time", "pareto", names,
                          {"metric": m, "truth": "each case against its FE run (P2, Taylor-Hood from nu 0.49; the base layer at 0.7 mm, the rest at 1.0 mm)"}) for m in ("pressure_l2_rel_error", "displacement_rel_error")]
    goals = []
    for variant in COUPLED_VARIANTS:
        pairs = tuple((n, n.replace(f"-{variant}-", "-springs-", 1)) for n in names if f"-{variant}-" in n)
        bed = VARIANTS[variant][1]
        goals.append(Analysis(
            "goal" if variant == "coupled" else f"goal-{variant}",
            f"The goal, {bed}: within 5 % of the FE up to nu 0.42 and 10 % up to 0.499 (displacement, peak, area), "
            "pressure-field L2 at most half the independent springs'. Flagged where not met", "goal", tuple(n for pair in pairs for n in pair),
            {**GOAL, "pairs": pairs, "note": "Errors are |coupled - FE| / FE; the L2 ratio is the coupled bed's pressure-field L2 error over the independent springs' against the same FE run. "
             "Figures: <model>-poisson (the three beds' errors against nu, the goal's lines dashed) and layer-thickness. "
             + ("At nu <= 0.25 the thin-layer correction vanishes or changes sign (c2(nu) = nu (4 nu - 1) / (6 (1 - nu)^2)), so the L2 ratio stays near 1 there by construction."
                if variant == "coupled" else "The two-pole symbol also models the surface's sag around a load at short waves, so it differs from the springs at every nu.")}))
    return Campaign(
        "thin-layer",
        "Coupled thin-layer bed vs independent springs vs the FE continuum (layer and slab; cylinder, ideal and subject-like ankles), sweeping Poisson's ratio 0 .. 0.499, the layer thickness 1-3 mm and the load 333-4190 N. "
        "FE P2 (Taylor-Hood from nu 0.49): the base layer (2 mm, 333 N) at 0.7 mm, every other case at 1.0 mm (the fe-convergence study's finest and middle levels, each with its estimated error); one FE run shared by the three variants of each point (Pade, two-pole, springs). The issue's goal is the analyses 'goal' (Pade) and 'goal-two-pole' (flagged where not met), not a failure.",
        cases,
        tuple(figures),
        (*goals, *analyses),
    )
