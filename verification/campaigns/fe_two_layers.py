"""``fe-two-layers``: the FE of two deformable layers (fem_reference.two_body) against Hertz line
contact of two elastic cylinders and two confined layers in series, three meshes each, with
observed orders (docs/method.md#two-deformable-layers)."""

from __future__ import annotations

from verification.campaign_model import Analysis, Campaign, Case, Figure
from verification.campaigns.fe_analytic import CONFINED_BASIS, CONFINED_METRICS, CONFINED_TOL, HERTZ_METRICS
from verification.verdicts import FE_CONVERGENCE, Basis

#: wall time with 2 jobs on 2 cores, nothing cached (measured 2026-11-28: 372 s at load 4-7, 93 s of CPU time)
EXPECTED_TIME_S = 372.0

CYLINDER_SIZES_MM = (0.4, 0.2, 0.1)  # contact element size = slice thickness; 10x that at 15 mm (ratio 2)
TWO_LAYER_SIZES_MM = (2.0, 1.0, 0.5)  # 10 x 8 mm, 2 + 1 mm: (5, 4) squares and (1, 1) layers ... (20, 16) and (4, 2)

CYLINDERS_REASON = ("the two-layer FE's mesh study (docs/method.md#two-deformable-layers, P2): peak pressure +2.2 / +1.4 / +0.8 %, "
                    "half-width from the contact area -5.0 / -2.7 / -1.3 % at 0.4 / 0.2 / 0.1 mm; the coarsest mesh is judged "
                    "through the observed orders only")


def _cylinder_tolerance(size_mm: float) -> dict[str, float]:
    """The mesh study's errors at this mesh, rounded up: 1 % (peak) and 2 % (half-width) at 0.1 mm,
    2 % and 3 % at 0.2 mm; none at 0.4 mm (orders only)."""
    if size_mm <= min(CYLINDER_SIZES_MM):
        return {"peak_pressure_rel_error": 0.01, "half_width_rel_error": 0.02}
    if size_mm <= 0.2:
        return {"peak_pressure_rel_error": 0.02, "half_width_rel_error": 0.03}
    return {}


def _cases() -> list[Case]:
    cases = []
    for size in CYLINDER_SIZES_MM:
        tolerance = _cylinder_tolerance(size)
        cases.append(Case(
            f"fe-hertz-cylinders-h{size:g}",
            f"two-layer FE (P2): two equal elastic cylinders R 20 mm, a = 1 mm; contact element size {size:g} mm: p0, half-width",
            "fe-problem:hertz-cylinders",
            ("fe-problem:hertz-cylinders", "closed-form:hertz-cylinders"),
            HERTZ_METRICS,
            tolerance,
            options={"mesh_size_mm": size, "element": "P2"},
            basis={m: Basis(FE_CONVERGENCE, CYLINDERS_REASON) for m in tolerance},
            params={"mesh_size_mm": size},
        ))
    for size in TWO_LAYER_SIZES_MM:
        cases.append(Case(
            f"fe-two-layer-confined-h{size:g}",
            f"two-layer FE (P2): confined layers 2 mm (E 10.35) on 1 mm (E 5, nu 0.3), 120 N, mesh size {size:g} mm: "
            "d = p (h_M / E'_M + h_F / E'_F)",
            "fe-problem:two-layer-confined",
            ("fe-problem:two-layer-confined", "closed-form:two-layer-confined"),
            CONFINED_METRICS,
            {m: CONFINED_TOL for m in CONFINED_METRICS},
            options={"mesh_size_mm": size, "element": "P2"},
            basis={m: CONFINED_BASIS for m in CONFINED_METRICS},
            params={"mesh_size_mm": size},
        ))
    return cases


def _figures() -> tuple[Figure, ...]:
    return (
        Figure(
            "fe-two-cylinders-convergence",
            "Two-layer FE, two equal elastic cylinders (P2): errors against Hertz vs contact element size (dotted: slope 1)",
            "sweep",
            tuple(f"fe-hertz-cylinders-h{h:g}" for h in CYLINDER_SIZES_MM),
            x="mesh_size_mm",
            y=("peak_pressure_rel_error", "half_width_rel_error", "half_width_fit_rel_error"),
            logx=True,
            logy=True,
            reference_slope=1.0,
        ),
    )


def _analyses() -> tuple[Analysis, ...]:
    cylinders = tuple(f"fe-hertz-cylinders-h{h:g}" for h in CYLINDER_SIZES_MM)
    stack = tuple(f"fe-two-layer-confined-h{h:g}" for h in TWO_LAYER_SIZES_MM)
    return (
        Analysis(
            "fe-two-layer-orders",
            "Observed convergence orders of the two-layer FE (P2; minimum orders below the mesh study's, which are stated in docs/method.md)",
            "order",
            cylinders + stack,
            {
                "checks": [
                    # measured 2.3: the approach converges as the one-body solver's does
                    {"label": "two cylinders: approach (Richardson, no closed form)", "cases": list(cylinders), "x": "mesh_size_mm",
                     "metric": "a_displacement_norm_mm", "mode": "richardson", "min_order": 1.5},
                    # measured 0.64, 0.88: the peak on facetted arcs (the one-body solver on the same meshes: 0.72, 0.68)
                    {"label": "two cylinders: peak pressure vs p0", "cases": list(cylinders), "x": "mesh_size_mm",
                     "metric": "peak_pressure_rel_error", "mode": "vs-exact", "min_order": 0.5, "monotone": True},
                    # measured 0.87, 1.09: the area of the facets in contact, first order in the element size
                    {"label": "two cylinders: half-width (contact area / slice) vs a", "cases": list(cylinders), "x": "mesh_size_mm",
                     "metric": "half_width_rel_error", "mode": "vs-exact", "min_order": 0.7, "monotone": True},
                    {"label": "two cylinders: half-width (elliptic fit) vs a", "cases": list(cylinders), "x": "mesh_size_mm",
                     "metric": "half_width_fit_rel_error", "mode": "vs-exact"},
                    {"label": "two confined layers: peak pressure vs F/A", "cases": list(stack), "x": "mesh_size_mm",
                     "metric": "peak_pressure_rel_error", "mode": "vs-exact"},
                    {"label": "two confined layers: displacement vs p (h_M / E'_M + h_F / E'_F)", "cases": list(stack), "x": "mesh_size_mm",
                     "metric": "displacement_rel_error", "mode": "vs-exact"},
                ],
                "roundoff": 1e-9,  # errors below this on every mesh: exact, no order
            },
        ),
    )


def campaign() -> Campaign:
    return Campaign(
        "fe-two-layers",
        "The two-layer FE (both cartilage layers deformable, fem_reference.two_body, P2) against Hertz line contact of two elastic "
        "cylinders (peak pressure, half-width) and two confined layers in series, three meshes each, with observed orders.",
        tuple(_cases()),
        _figures(),
        _analyses(),
    )
