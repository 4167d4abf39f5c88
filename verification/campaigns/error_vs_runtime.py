"""``error-vs-runtime``: error against wall time of both sides on ideal standing (333 N, no
ligaments): DEM over the ideal ankle's mesh size, with independent springs (``dem-<size>``) and
with the coupled thin layer (``dem-coupled-<size>``, ``cartilage.coupling = "thin-layer"``), the
FE slab over P1 mesh sizes (all against the FE slab P2 at 1.0 mm: the truth, side
``fe-slab-truth``, one run shared by all of them: it ignores the spring mesh and the coupling), and EDEM over the step count of a
0 -> 333 N ramp (against EDEM at 128 steps: side ``edem-128-steps``). Figure: error vs side a's
wall time on log axes; analysis: the Pareto front per truth (points no other beats in both error and time)."""

from __future__ import annotations

from verification.campaign_model import THESIS_ANKLE, THESIS_BED, Analysis, Campaign, Case, Figure
from verification.campaign_model import ramp_overrides
from verification.fe_comparison import CHECK_METRICS, FE_COMPARE_BASIS, SANITY_BASIS
from verification.sides import TRUTH_STEPS

#: wall time with 2 jobs on 2 cores, nothing cached (measured: 125 s at load 3-5 on the shared 2-core machine: one FE
#: truth run (P2 at 1.0 mm, shared by the 15 cases against it; it was nine runs, 600 s estimated) and three P1 meshes)
EXPECTED_TIME_S = 125.0


ERT_SCENE = "ideal-standing"
ERT_LOAD_N = 333.0
ERT_DEM_SIZES_MM = (2.0, 1.4, 0.94, 0.66, 0.47, 0.33)
ERT_FE_P1_SIZES_MM = (1.0, 0.7, 0.5)
ERT_STEPS = (8, 16, 32, 64)
ERT_METRICS = ("pressure_l2_rel_error", "regularised_peak_pressure_rel_error", "displacement_rel_error")
ERT_TRUTH_NOTE = (
    "Truth: DEM and FE P1 points against the FE slab P2 at 1.0 mm (side fe-slab-truth; within 0.7 % of P2 at 0.7 mm, fem_reference.scene_run); "
    "EDEM step counts against EDEM at 128 steps (side edem-128-steps). DEM errors level off at the model gap (independent springs vs continuum), not at zero."
)


#: the DEM families: (name prefix, extra overrides, what)
ERT_DEM_FAMILIES = (("dem", THESIS_BED, "independent springs"), ("dem-coupled", {"cartilage.coupling": "thin-layer"}, "coupled thin layer"))


def _ert_cases() -> list[Case]:
    base = {"ligaments": [], **THESIS_ANKLE}  # the threshold law on the thesis's geometry: the FE slab's twin
    cases = []
    for family, extra, what in ERT_DEM_FAMILIES:
        for size in ERT_DEM_SIZES_MM:
            cases.append(
                Case(
                    f"{family}-{size:g}",
                    f"DEM ({what}), ideal standing 333 N without ligaments, springs on a {size:g} mm mesh, vs the FE slab P2 at 1.0 mm (the truth)",
                    ERT_SCENE,
                    ("dem", "fe-slab-truth"),
                    ERT_METRICS + CHECK_METRICS,
                    {**{m: 10.0 for m in ERT_METRICS}, "force_residual_rel": 1e-6, "non_finite_outputs": 0.0},
                    overrides={**base, "geometry.mesh_size_mm": size, **extra},
                    params={"mesh_size_mm": size},
                    basis=dict(FE_COMPARE_BASIS),
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
                basis=dict(SANITY_BASIS),
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
                basis=dict(FE_COMPARE_BASIS),
            )
        )
    return cases


def campaign() -> Campaign:
    cases = tuple(_ert_cases())
    names = tuple(c.name for c in cases)
    return Campaign(
        "error-vs-runtime",
        "Error against wall time on ideal standing (333 N, no ligaments): DEM (independent springs and coupled thin layer) over the spring mesh (2.0 .. 0.33 mm) and FE P1 (1.0, 0.7, 0.5 mm) against the FE slab P2 at 1.0 mm; "
        "EDEM over 8 .. 64 ramp increments against 128. P2 at 0.7 mm (8 min, 8 GB) is left out. Log-log figure and the Pareto front.",
        cases,
        (
            Figure("error-vs-time", "Error against wall time of side a (log-log); families: dem and dem-coupled (mesh), fe-p1 (mesh), edem (steps); dashed: Pareto front per truth (fe-slab-truth, edem-128-steps)", "error-vs-time", names, y=ERT_METRICS, logx=True, logy=True),
            Figure("dem-mesh", "DEM against the FE truth vs the spring mesh size, independent springs and coupled thin layer", "sweep",
                   tuple(f"{f}-{s:g}" for f, _e, _w in ERT_DEM_FAMILIES for s in ERT_DEM_SIZES_MM), x="mesh_size_mm", y=ERT_METRICS, logx=True, logy=True,
                   series=tuple((what, tuple(f"{f}-{s:g}" for s in ERT_DEM_SIZES_MM)) for f, _e, what in ERT_DEM_FAMILIES)),
            Figure("edem-steps", "EDEM against 128 steps vs the step count (dotted: slope -1)", "sweep", tuple(f"edem-{n}" for n in ERT_STEPS), x="steps", y=ERT_METRICS, logx=True, logy=True, reference_slope=-1.0),
        ),
        tuple(
            Analysis(f"pareto-{m}", f"Pareto front of {m} against wall time", "pareto", names, {"metric": m, "truth": ERT_TRUTH_NOTE}) for m in ("pressure_l2_rel_error", "displacement_rel_error")
        ),
    )
