"""``sensitivity``: h_max x ligament modulus, 20 x 20 EDEM stances (the thesis's fig. 4.3.10), on
the thesis's ankle, law and bed (named in the overrides: the scene's default is the gap law on
both layers, whose answer the window does not set)."""

from __future__ import annotations

from verification.campaign_model import THESIS_ANKLE, THESIS_BED, Analysis, Campaign, Case, Expect, Figure
from verification.campaigns.stance import THESIS_FLAG_REL
from verification.verdicts import INVARIANT, Basis

#: wall time with 2 jobs on 2 cores, nothing cached (measured: 63 s at load 2-4, 77-119 s at load
#: 5-7, 133 s at load 7-10, where the code before the geometry cache and the map-less, unflushed
#: case writes took 143-168 s and 184 s; that code took 55 s at load below 2.5). Its CPU time
#: (benchmarks/bench_campaign_throughput.py, 2026-11-26 at load 9-12): 113 ms per case, start-up
#: 2.2 s, report 1.1 s, so 24.5 s on a quiet machine (the 19 s measured there once)
EXPECTED_TIME_S = 90.0


SENSITIVITY_SCENE = "ideal-stance"
SENSITIVITY_GRID = 20
SENSITIVITY_HMAX_MM = (2.5, 4.5)
SENSITIVITY_MODULUS_MPA = (200.0, 350.0)
THESIS_SENSITIVITY = {"hmax_change": -0.30, "modulus_change": 0.03}  # docs/references.md#the-thesiss-figures: peak -30 % from h_max 2.5 to 4.5; ~3 % over the moduli


def _grid(bounds: tuple[float, float], n: int) -> list[float]:
    lo, hi = bounds
    return [round(lo + (hi - lo) * k / (n - 1), 9) for k in range(n)]


def sensitivity_case_name(h_max_mm: float, modulus_mpa: float) -> str:
    return f"hmax{h_max_mm:.4f}-E{modulus_mpa:.2f}"


def _sensitivity_cases(n: int = SENSITIVITY_GRID) -> list[Case]:
    cases = []
    for h in _grid(SENSITIVITY_HMAX_MM, n):
        for e in _grid(SENSITIVITY_MODULUS_MPA, n):
            cases.append(
                Case(
                    sensitivity_case_name(h, e),
                    f"EDEM ideal stance, h_max {h:.4g} mm, ligament modulus {e:.4g} MPa (all four ligaments); the thesis's geometry, law and bed "
                    "(no cartilage, threshold law, independent springs, named in the overrides) as its fig. 4.3.10 is compared",
                    SENSITIVITY_SCENE,
                    ("edem",),
                    ("a_peak_pressure_mpa", "a_mean_contact_area_mm2", "outcome_mismatch"),
                    {"outcome_mismatch": 0.0},  # every run of the grid must solve its stance
                    basis={"outcome_mismatch": Basis(INVARIANT, "the run must solve every time point: a requirement, not an accuracy claim")},
                    overrides={**THESIS_BED, **THESIS_ANKLE, "cartilage.max_spring_length_mm": h, "ligaments[*].youngs_modulus_mpa": e},
                    expect=Expect("converges"),
                    options={"frames": "none"},  # the metrics need the time series only: no pressure map to write
                    params={"h_max_mm": h, "ligament_modulus_mpa": e},
                )
            )
    return cases


def campaign(n: int = SENSITIVITY_GRID) -> Campaign:
    cases = tuple(_sensitivity_cases(n))
    names = tuple(c.name for c in cases)
    return Campaign(
        "sensitivity",
        f"Peak pressure (max over the ideal stance, EDEM) on a {n} x {n} grid of h_max in [2.5, 4.5] mm and ligament modulus in [200, 350] MPa (thesis fig. 4.3.10).",
        cases,
        (
            Figure("sensitivity-heatmap", "Peak pressure over the stance (MPa) against h_max and the ligament modulus", "heatmap", names, x="h_max_mm", y=("a_peak_pressure_mpa",), param2="ligament_modulus_mpa"),
            Figure("sensitivity-cuts", "Line cuts: peak pressure against h_max at three moduli, against the modulus at three h_max", "cuts", names, x="h_max_mm", y=("a_peak_pressure_mpa",), param2="ligament_modulus_mpa"),
        ),
        (
            Analysis(
                "sensitivity-changes",
                "Relative change of the peak pressure across each parameter's range, beside the thesis's (docs/references.md#the-thesiss-figures); reported, no verdict",
                "sensitivity",
                names,
                {"x": "h_max_mm", "y": "ligament_modulus_mpa", "metric": "a_peak_pressure_mpa", "thesis_x_change": THESIS_SENSITIVITY["hmax_change"], "thesis_y_change": THESIS_SENSITIVITY["modulus_change"], "flag_rel": THESIS_FLAG_REL},
            ),
        ),
    )
