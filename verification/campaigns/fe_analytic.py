"""``fe-analytic``: the FE reference against Hertz line contact and confined compression, three
meshes each, with observed orders."""

from __future__ import annotations

from verification.campaign_model import Analysis, Campaign, Case, Figure
from verification.metrics import COMPARISON_METRICS
from verification.verdicts import CLOSED_FORM, FE_CONVERGENCE, Basis

#: wall time with 2 jobs on 2 cores, nothing cached (measured by tests/verification/test_verification_fe_analytic.py on an idle machine)
EXPECTED_TIME_S = 25.0


HERTZ_SIZES_MM = (0.4, 0.2, 0.1)  # contact element size = slice thickness; far size 10x (ratio 2)
CONFINED_SIZES_MM = (2.0, 1.0, 0.5)  # slab 10 x 8 x 2 mm: (5, 4, 1), (10, 8, 2), (20, 16, 4) boxes
HERTZ_METRICS = ("peak_pressure_rel_error", "half_width_rel_error", "half_width_fit_rel_error", "mean_pressure_rel_error", "pressure_l2_rel_error", "a_displacement_norm_mm")
CONFINED_METRICS = COMPARISON_METRICS


HERTZ_REASON = ("the FE mesh-convergence study (tests/fem_reference, P2, observed order ~2): 3 % at contact elements <= 0.25 mm, "
                "1 % (peak) and 2 % (half-width) on the finest mesh; the coarsest mesh is judged through the observed order only")
CONFINED_TOL = 1e-6
CONFINED_BASIS = Basis(CLOSED_FORM, "the exact solution (uniform strain) lies in the P2 space and Nitsche's method is consistent: "
                                    "what remains is the Newton solve, far below 1e-6 (measured ~1e-14)")


def _hertz_tolerance(size_mm: float) -> dict[str, float]:
    """tests/fem_reference (P2): 3 % at contact size <= 0.25 mm (test_fe_hertz, coarse); on the
    finest of the three convergence meshes 1 % (peak) and 2 % (half-width) (test_fe_convergence).
    The coarsest mesh is judged through the observed order only (the tests do the same)."""
    if size_mm <= min(HERTZ_SIZES_MM):
        return {"peak_pressure_rel_error": 0.01, "half_width_rel_error": 0.02}
    if size_mm <= 0.25:
        return {"peak_pressure_rel_error": 0.03, "half_width_rel_error": 0.03}
    return {}


def _fe_analytic_cases() -> list[Case]:
    cases = []
    for size in HERTZ_SIZES_MM:
        cases.append(
            Case(
                f"fe-hertz-line-h{size:g}",
                f"FE (P2) Hertz line contact, rigid cylinder R 20 mm on a 20 mm block, a = 1 mm; contact element size {size:g} mm: p0, half-width",
                "fe-problem:hertz-line",
                ("fe-problem:hertz-line", "closed-form:hertz-line"),
                HERTZ_METRICS,
                _hertz_tolerance(size),
                options={"mesh_size_mm": size, "element": "P2"},
                basis={m: Basis(FE_CONVERGENCE, HERTZ_REASON) for m in _hertz_tolerance(size)},
                params={"mesh_size_mm": size},
            )
        )
    for size in CONFINED_SIZES_MM:
        cases.append(
            Case(
                f"fe-confined-compression-h{size:g}",
                f"FE (P2) confined compression, 10 x 8 x 2 mm slab, 120 N, mesh size {size:g} mm: p = F/A, d = p h / E' (p = E' d / h)",
                "fe-problem:confined-compression",
                ("fe-problem:confined-compression", "closed-form:confined-compression"),
                CONFINED_METRICS,
                {m: CONFINED_TOL for m in COMPARISON_METRICS},
                options={"mesh_size_mm": size, "element": "P2"},
                basis={m: CONFINED_BASIS for m in COMPARISON_METRICS},
                params={"mesh_size_mm": size},
            )
        )
    return cases


def _fe_analytic_figures() -> tuple[Figure, ...]:
    return (
        Figure(
            "fe-hertz-convergence",
            "FE Hertz line contact (P2): errors against the closed form vs contact element size (dotted: slope 2)",
            "sweep",
            tuple(f"fe-hertz-line-h{h:g}" for h in HERTZ_SIZES_MM),
            x="mesh_size_mm",
            y=("peak_pressure_rel_error", "half_width_rel_error", "half_width_fit_rel_error"),
            logx=True,
            logy=True,
            reference_slope=2.0,
        ),
        Figure(
            "fe-confined-convergence",
            "FE confined compression (P2): errors against p = E' d / h vs mesh size (round-off: the linear field is in the FE space)",
            "sweep",
            tuple(f"fe-confined-compression-h{h:g}" for h in CONFINED_SIZES_MM),
            x="mesh_size_mm",
            y=("peak_pressure_rel_error", "displacement_rel_error", "pressure_l2_rel_error"),
            logx=True,
            logy=True,
        ),
    )


def _fe_analytic_analyses() -> tuple[Analysis, ...]:
    hertz = tuple(f"fe-hertz-line-h{h:g}" for h in HERTZ_SIZES_MM)
    confined = tuple(f"fe-confined-compression-h{h:g}" for h in CONFINED_SIZES_MM)
    return (
        Analysis(
            "fe-orders",
            "Observed convergence orders of the FE reference (P2; minimum orders of tests/fem_reference/test_fe_convergence.py)",
            "order",
            hertz + confined,
            {
                "checks": [
                    {"label": "Hertz peak pressure vs p0", "cases": list(hertz), "x": "mesh_size_mm", "metric": "peak_pressure_rel_error", "mode": "vs-exact", "min_order": 1.5, "monotone": True},
                    {"label": "Hertz bone displacement (Richardson, no closed form)", "cases": list(hertz), "x": "mesh_size_mm", "metric": "a_displacement_norm_mm", "mode": "richardson", "min_order": 1.5},
                    {"label": "Hertz half-width (contact area / slice) vs a", "cases": list(hertz), "x": "mesh_size_mm", "metric": "half_width_rel_error", "mode": "vs-exact"},
                    {"label": "Hertz half-width (elliptic fit) vs a", "cases": list(hertz), "x": "mesh_size_mm", "metric": "half_width_fit_rel_error", "mode": "vs-exact"},
                    {"label": "confined compression peak pressure vs F/A", "cases": list(confined), "x": "mesh_size_mm", "metric": "peak_pressure_rel_error", "mode": "vs-exact"},
                    {"label": "confined compression displacement vs p h / E'", "cases": list(confined), "x": "mesh_size_mm", "metric": "displacement_rel_error", "mode": "vs-exact"},
                ],
                "roundoff": 1e-9,  # errors below this on every mesh: exact, no order
            },
        ),
    )


def campaign() -> Campaign:
    return Campaign(
        "fe-analytic",
        "The FE reference (fem_reference core, P2) against closed forms: Hertz line contact (peak pressure, half-width) and confined compression (p = E' d / h), three meshes each, with observed orders.",
        tuple(_fe_analytic_cases()),
        _fe_analytic_figures(),
        _fe_analytic_analyses(),
    )
