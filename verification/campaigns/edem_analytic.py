"""``edem-analytic``: EDEM/DEM against closed forms (flat plates, tilted plane, cylinder on a plane,
the log law under a ramp, hemisphere thickness convergence)."""

from __future__ import annotations

from verification.campaign_model import Campaign, Case, Figure, uniform_tolerance
from verification.campaign_model import ramp_overrides
from verification.closed_forms import confined_modulus_mpa, log_law_edem_max_error
from verification.metrics import SPEC8_METRICS


PLATES = "flat-plates.toml"  # 20 x 20 mm, gap 2 mm, E 10.35 MPa, nu 0.42, threshold, 400 N
PLATE_AREA_MM2 = 400.0
LOG_LAW_FORCE_N = 10_000.0
LOG_LAW_STEPS = (4, 8, 16, 32, 64, 128)
HEMISPHERE_LEVELS = (1, 2, 3, 4, 5, 6)


def _analytic_cases() -> list[Case]:
    cases = [
        Case(
            "flat-plates-dem",
            "DEM, parallel plates 2 mm apart, 400 N: p = F/A, d = F h/(E' A)",
            PLATES,
            ("dem", "closed-form:flat-plates"),
            SPEC8_METRICS,
            uniform_tolerance(1e-9),
        ),
        Case(
            "flat-plates-edem",
            "EDEM (one step from the initial pose) on the same plates: same closed form",
            PLATES,
            ("edem", "closed-form:flat-plates"),
            SPEC8_METRICS,
            uniform_tolerance(1e-9),
        ),
        Case(
            "flat-plates-dem-series",
            "DEM over 100, 200, 400 N (each time point static): p = F/A, d = F h/(E' A) per point",
            PLATES,
            ("dem", "closed-form:flat-plates"),
            SPEC8_METRICS,
            uniform_tolerance(1e-9),
            overrides={"load.time_s": [0.0, 1.0, 2.0], "load.force_n": [[0.0, 0.0, 100.0], [0.0, 0.0, 200.0], [0.0, 0.0, 400.0]]},
        ),
        Case(
            "tilted-plane-dem",
            "DEM, plate under a plane tilted 3 deg, rotations fixed: p(x) = E' d / h(x) (midpoint-rule O(dx^2) from the integral)",
            "tilted-plane.toml",
            ("dem", "closed-form:tilted-plane"),
            SPEC8_METRICS,
            uniform_tolerance(1e-3),
        ),
        Case(
            "cylinder-plane-dem",
            "DEM, cylinder R 20 mm under a plane (mesh 0.94 mm): discrete foundation p = E' d cos(phi)/h(phi); "
            "L2 dominated by the faceted candidate boundary",
            "cylinder-plane.toml",
            ("dem", "closed-form:cylinder-plane"),
            SPEC8_METRICS,
            {**uniform_tolerance(0.01), "pressure_l2_rel_error": 0.05},
            params={"mesh_size_mm": 0.94},
        ),
        Case(
            "cylinder-plane-dem-fine",
            "the same cylinder meshed at 0.47 mm: the faceting errors shrink",
            "cylinder-plane.toml",
            ("dem", "closed-form:cylinder-plane"),
            SPEC8_METRICS,
            {**uniform_tolerance(0.002), "pressure_l2_rel_error": 0.005},
            overrides={"geometry.mesh_size_mm": 0.47},
            params={"mesh_size_mm": 0.47},
        ),
    ]
    # Log law: EDEM after k of n equal increments gives h0 (1 - (1 - x/n)^k), x = F / (E' A),
    # whose error against the log law is known exactly (closed_forms.log_law_edem_error); the
    # case tolerance is its largest value over the ramp's time points + 1 %: first order in 1/n.
    x = LOG_LAW_FORCE_N / (confined_modulus_mpa(10.35, 0.42) * PLATE_AREA_MM2)
    for n in LOG_LAW_STEPS:
        cases.append(
            Case(
                f"log-law-n{n}",
                f"EDEM, flat plates, ramp 0 -> {LOG_LAW_FORCE_N:g} N in {n} increments against d = h0 (1 - exp(-F/(E' A)))",
                "log-law-ramp.toml",
                ("edem", "closed-form:log-law"),
                ("displacement_rel_error", "peak_pressure_rel_error", "pressure_l2_rel_error"),
                {"displacement_rel_error": 1.01 * log_law_edem_max_error(x, n), "peak_pressure_rel_error": 1e-9, "pressure_l2_rel_error": 1e-9},
                overrides=ramp_overrides(n, LOG_LAW_FORCE_N),
                params={"steps": n},
            )
        )
    for level in HEMISPHERE_LEVELS:
        tolerance = {"thickness_faceting_ratio": 1.0}
        if level == HEMISPHERE_LEVELS[-1]:
            tolerance.update(thickness_mean_rel_error=1e-3, thickness_sd_mm=5e-5)  # thesis: 0.499, sd 1.5e-5
        cases.append(
            Case(
                f"hemisphere-L{level}",
                f"ray-cast thickness, target hemisphere with {level} subdivisions (thesis 4.2.2): exact 0.5",
                "hemisphere-convergence",
                ("dem", "closed-form:hemisphere-thickness"),
                ("thickness_mean_mm", "thickness_sd_mm", "thickness_mean_rel_error", "thickness_faceting_ratio"),
                tolerance,
                overrides={"geometry.subdivisions": level},
                params={"subdivisions": level},
            )
        )
    return cases


def _hemisphere_figure() -> Figure:
    return Figure(
        "hemisphere-thickness",
        "Hemisphere thickness (exact 0.5) against target subdivisions",
        "sweep",
        tuple(f"hemisphere-L{k}" for k in HEMISPHERE_LEVELS),
        x="subdivisions",
        y=("thickness_mean_mm", "thickness_sd_mm"),
        logy=(False, True),
        exact={"thickness_mean_mm": 0.5},
    )


def _analytic_figures() -> tuple[Figure, ...]:
    return (
        _hemisphere_figure(),
        Figure(
            "log-law-convergence",
            "EDEM against the log law: displacement error against step count",
            "sweep",
            tuple(f"log-law-n{n}" for n in LOG_LAW_STEPS),
            x="steps",
            y=("displacement_rel_error",),
            logx=True,
            logy=True,
            reference_slope=-1.0,
        ),
        Figure("log-law-n8-displacement", "Log law, 8 increments: displacement against time", "timeseries", ("log-law-n8",), column="disp_z_mm"),
        Figure(
            "cylinder-refinement",
            "Cylinder under a plane: errors against mesh size",
            "sweep",
            ("cylinder-plane-dem", "cylinder-plane-dem-fine"),
            x="mesh_size_mm",
            y=("displacement_rel_error", "pressure_l2_rel_error"),
            logx=True,
            logy=True,
        ),
    )



def campaign() -> Campaign:
    return Campaign(
        "edem-analytic",
        "EDEM/DEM against closed forms: flat plates, tilted plane, cylinder on a plane, the log law under a ramp, hemisphere thickness convergence.",
        tuple(_analytic_cases()),
        _analytic_figures(),
    )
