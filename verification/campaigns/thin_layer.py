"""``thin-layer``: the coupled thin-layer bed (``cartilage.coupling = "thin-layer"``) and the
independent springs against the FE continuum, on the bonded cylinder layer (``cylinder-layer``,
gap law, DEM vs the FE layer) and the ideal ankle (``ideal-standing``, threshold law, DEM vs the
FE slab, no ligaments). Sweeps: Poisson's ratio (0, 0.3, 0.42, 0.45, 0.49, 0.499) at each layer
thickness (1, 2, 3 mm: ``geometry.plafond_gap_mm`` and ``cartilage.thickness_mm`` together) at
333 N on the cylinder layer, and at 333 N on the ideal ankle; loads 333, 1000, 4190 N at nu 0.42
and 0.49 (cylinder layer 2 mm; ideal ankle). Every point is two cases, ``<model>-coupled-...`` and
``<model>-springs-...``, each against its own FE run (the runner caches per case).

FE: coarse on purpose (a shared 2-core machine): P2 at 1.0 mm (Taylor-Hood from nu 0.49), the
layer with its default two elements through the thickness: 10 s to 3 min per run on the
shared 2-core machine (the Taylor-Hood runs are the slow ones). Tolerances are
generous (the campaign measures; it fails only when something is broken); the issue's goal
(within 10 % of FE up to nu 0.499, 5 % up to 0.42, L2 at most half the springs') is read off the
tables and figures, not enforced."""

from __future__ import annotations

from typing import Any

from verification.campaign_model import Analysis, Campaign, Case, Figure
from verification.campaigns.cylinder_plane import ERROR_PANELS, FE_COARSE, FE_COMPARE_BASIS, FE_COMPARE_METRICS, FE_COMPARE_TOL, FE_TABLE_COLUMNS

#: wall time with 2 jobs on 2 cores, nothing cached (estimate: its FE runs take 10 s to 3 min each,
#: from the docstring above; 64 cases, about a minute each on average, two jobs)
EXPECTED_TIME_S = 1900.0

NUS = (0.0, 0.3, 0.42, 0.45, 0.49, 0.499)
THICKNESS_MM = (1.0, 2.0, 3.0)
LOADS_N = (333.0, 1000.0, 4190.0)
LOAD_NUS = (0.42, 0.49)
BASE_LOAD_N, BASE_THICKNESS_MM = 333.0, 2.0
VARIANTS = {"coupled": {"cartilage.coupling": "thin-layer"}, "springs": {}}
#: (model, scene, sides, what)
MODELS = (
    ("layer", "cylinder-layer", ("dem", "fe-layer"), "cylinder (R 20 mm) with a bonded layer on a plane, gap-law DEM vs the FE layer"),
    ("slab", "ideal-standing", ("dem", "fe-slab"), "ideal ankle (R 20 mm, 114 deg, plafond 1.5 mm above), threshold-law DEM vs the FE slab, no ligaments"),
)


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
    return list(dict.fromkeys(points))


def _cases() -> list[Case]:
    info = {m: (scene, sides, what) for m, scene, sides, what in MODELS}
    cases = []
    for model, load, thickness, nu in _points():
        scene, sides, what = info[model]
        overrides: dict[str, Any] = {"load.force_n": [0.0, 0.0, load], "cartilage.poissons_ratio": nu}
        if thickness is None:
            overrides["ligaments"] = []
        else:
            overrides.update({"geometry.plafond_gap_mm": thickness, "cartilage.thickness_mm": thickness})
        element = "Taylor-Hood P2-P1" if nu >= 0.49 else "P2"
        for variant, extra in VARIANTS.items():
            cases.append(
                Case(
                    case_name(model, variant, load, thickness, nu),
                    f"{what}; {'coupled thin layer' if extra else 'independent springs'}: {load:g} N, nu {nu:g}"
                    + (f", layer {thickness:g} mm" if thickness is not None else "") + f"; FE {element} at 1.0 mm. Measured, not judged",
                    scene,
                    sides,
                    FE_COMPARE_METRICS,
                    dict(FE_COMPARE_TOL),
                    overrides={**overrides, **extra},
                    options=dict(FE_COARSE),
                    params={"load_n": load, "poissons_ratio": nu, "thickness_mm": thickness or 0.0},
                    maps=(model, load, thickness, nu) == ("layer", BASE_LOAD_N, BASE_THICKNESS_MM, 0.49),
                    basis=dict(FE_COMPARE_BASIS),
                )
            )
    return cases


def campaign() -> Campaign:
    cases = tuple(_cases())
    names = tuple(c.name for c in cases)
    figures, analyses = [], []
    sweeps = [(f"layer-t{t:g}", f"cylinder layer {t:g} mm, 333 N", "layer", BASE_LOAD_N, t) for t in THICKNESS_MM]
    sweeps.append(("slab", "ideal ankle vs the FE slab, 333 N", "slab", BASE_LOAD_N, None))
    for tag, what, model, load, t in sweeps:
        rows = []
        for variant in VARIANTS:
            series = tuple(case_name(model, variant, load, t, nu) for nu in NUS)
            rows += series
            figures.append(Figure(f"{tag}-{variant}-poisson", f"{what}: {variant} DEM errors against the FE vs Poisson's ratio", "sweep", series,
                                  x="poissons_ratio", y=ERROR_PANELS, logy=True))
        analyses.append(Analysis(f"{tag}-table", f"{what}: coupled and independent springs against the FE, by Poisson's ratio. Reported, no verdict", "table", tuple(rows), {"columns": FE_TABLE_COLUMNS}))
    for variant in VARIANTS:
        series = tuple(case_name("layer", variant, BASE_LOAD_N, t, 0.49) for t in THICKNESS_MM)
        figures.append(Figure(f"layer-thickness-{variant}", f"cylinder layer, 333 N, nu 0.49: {variant} DEM errors against the FE layer vs the thickness", "sweep", series,
                              x="thickness_mm", y=ERROR_PANELS, logy=True))
    load_rows = tuple(case_name(m, v, f, BASE_THICKNESS_MM if m == "layer" else None, nu) for m in ("layer", "slab") for v in VARIANTS for nu in LOAD_NUS for f in LOADS_N)
    analyses.append(Analysis("load-table", "Both models over the load (layer 2 mm; ideal ankle), nu 0.42 and 0.49. Reported, no verdict", "table", load_rows, {"columns": FE_TABLE_COLUMNS}))
    figures.append(Figure("error-vs-time", "Error against the DEM wall time, coupled vs independent springs (families: model-variant-load-thickness, points by nu); dashed: the Pareto front",
                          "error-vs-time", names, y=("pressure_l2_rel_error", "displacement_rel_error"), logx=True, logy=True))
    analyses += [Analysis(f"pareto-{m}", f"Pareto front of {m} against the DEM wall time", "pareto", names,
                          {"metric": m, "truth": "each case against its own FE run (P2 at 1.0 mm, Taylor-Hood from nu 0.49)"}) for m in ("pressure_l2_rel_error", "displacement_rel_error")]
    return Campaign(
        "thin-layer",
        "Coupled thin-layer bed vs independent springs vs the FE continuum (layer and slab), sweeping Poisson's ratio 0 .. 0.499, the layer thickness 1-3 mm and the load 333-4190 N. "
        "FE coarse: P2 at 1.0 mm (Taylor-Hood from nu 0.49), two elements through the layer. Measured, not judged.",
        cases,
        tuple(figures),
        tuple(analyses),
    )
