"""Verification campaigns as data (SPEC 1, 8): named lists of cases, each comparing two sides.

A :class:`Case` names a scene (a built-in scene or a TOML file of ``verification/scenes/``) with
``--set``-like overrides, the sides it runs (a subject and, optionally, the reference it is judged
against: ``edem``, ``dem``, ``fe-slab``, ``fe-layer``, ``fe-problem:<name>``, ``closed-form:<name>``), the metrics it
reports and the tolerance it is judged by (metric -> largest admissible value). Stability cases
also declare their expected outcome (:class:`Expect`): "converges" or "refused" with a message
matching a pattern. A :class:`Campaign` adds the figures of its HTML report.

An :class:`Analysis` is a campaign-level result computed after its cases from their metrics
(:mod:`verification.analyses`): observed convergence orders of a mesh sweep (judged against a
minimum order, like a tolerance), the thesis's figures beside ours (reported, large differences
flagged, no verdict), the relative changes of a parameter sweep and plain tables of metrics.

Campaigns: ``edem-analytic`` (EDEM/DEM against closed forms), ``stability`` (stiff and extreme
input, each ending in its declared outcome, no NaN anywhere), ``fe-analytic`` (the FE reference
against Hertz line contact and confined compression on three meshes each, with observed orders),
``stance`` (EDEM vs DEM over the built-in stance scenes, the thesis's figures beside ours, DEM
vs the FE slab at five instants, "unavailable" without ``fem_reference.run_scene``), ``sensitivity`` (h_max x ligament modulus,
20 x 20 EDEM stances, the thesis's fig. 4.3.10) and ``quick`` (a subset for CI).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from edem.errors import InputError
from verification.closed_forms import confined_modulus_mpa, log_law_edem_max_error
from verification.metrics import SERIES_METRICS, SPEC8_METRICS

SCENES_DIR = Path(__file__).resolve().parent / "scenes"

#: every metric a case may report, with what it measures
METRICS: dict[str, str] = {
    "peak_pressure_rel_error": "|peak_a - peak_b| / peak_b (max over compared time points), SPEC 8",
    "mean_pressure_rel_error": "relative error of the mean pressure (contact force / contact area), SPEC 8",
    "contact_area_rel_error": "relative error of the contact area, SPEC 8",
    "displacement_rel_error": "|u_a - u_b| / |u_b| of the bone displacement, SPEC 8",
    "pressure_l2_rel_error": "area-weighted L2 relative error of the pressure at a's spring centroids, SPEC 8",
    "thickness_mean_mm": "mean ray-cast spring length of side a (springs with a hit)",
    "thickness_sd_mm": "standard deviation of those lengths",
    "thickness_mean_rel_error": "|mean length - exact thickness| / exact thickness",
    "thickness_faceting_ratio": "|mean length - exact thickness| / faceting bound of the meshes (<= 1 expected)",
    "outcome_mismatch": "0 when side a ended in the declared outcome (converges / refused with the message), else 1",
    "non_finite_outputs": "number of NaN/inf values in side a's result directory",
    "force_residual_rel": "largest force residual of side a over the largest applied force",
    "half_width_rel_error": "|a_FE - a| / a: FE Hertz half-width (contact area / slice thickness) against the closed form",
    "half_width_fit_rel_error": "the same from an elliptic fit p^2 = p0^2 (1 - x^2/a^2) of the FE nodal pressure (edge-independent)",
}
_SERIES_DESCRIPTIONS = {
    "peak_pressure_mpa": "largest peak pressure over the time points",
    "mean_contact_area_mm2": "mean contact area over the time points",
    "max_superior_displacement_mm": "largest displacement of G along +z (superior) over the time points",
    "max_superior_displacement_percent": "when that happens, in % of the time span",
    "displacement_norm_mm": "|u| of G at the last time point (a value: Richardson's observed order needs no exact one)",
}
for _side in ("a", "b"):
    for _name in SERIES_METRICS:
        METRICS[f"{_side}_{_name}"] = f"side {_side}: {_SERIES_DESCRIPTIONS[_name]} (timeseries.csv)"
for _name in SERIES_METRICS:
    METRICS[f"a_at_b_{_name}"] = f"side a at side b's time points only: {_SERIES_DESCRIPTIONS[_name]}"

OUTCOMES = ("converges", "refused")


@dataclass(frozen=True)
class Expect:
    """The declared outcome of a stability case: "converges", or "refused" with a message pattern."""

    outcome: str
    message: str = ""  # regular expression (re.search) the refusal message must match
    warning: str = ""  # for "converges": a regular expression one of the run's warnings must match

    def __post_init__(self) -> None:
        if self.outcome not in OUTCOMES:
            raise ValueError(f"unknown outcome {self.outcome!r}: expected one of {OUTCOMES}")


@dataclass(frozen=True)
class Case:
    """One comparison: a scene, the sides it runs, the metrics it reports and its tolerance."""

    name: str
    description: str
    scene: str  # built-in scene name, or a TOML file name in verification/scenes/ (or a path)
    sides: tuple[str, ...]  # (a,) or (a, b): a is judged against the reference b
    metrics: tuple[str, ...]
    tolerance: dict[str, float] = field(default_factory=dict)  # metric -> max value
    overrides: dict[str, Any] = field(default_factory=dict)  # dotted scene keys, as --set
    expect: Expect | None = None
    options: dict[str, Any] = field(default_factory=dict)  # side options (FE: mesh_size_mm, degree)
    params: dict[str, float] = field(default_factory=dict)  # x values for the report's figures
    maps: bool = False  # render pressure maps of a against b in the report

    def scene_ref(self) -> str:
        """The argument for edem.scene.load_scene: a built-in name or an absolute TOML path."""
        if self.scene.endswith(".toml"):
            path = Path(self.scene)
            return str(path if path.is_absolute() else SCENES_DIR / path)
        return self.scene

    def definition(self) -> dict[str, Any]:
        """The JSON-able inputs that determine the case's results (its cache key hashes these)."""
        return {
            "name": self.name,
            "scene": self.scene,
            "sides": list(self.sides),
            "metrics": list(self.metrics),
            "overrides": self.overrides,
            "expect": None if self.expect is None else {"outcome": self.expect.outcome, "message": self.expect.message, "warning": self.expect.warning},
            "options": self.options,
        }


@dataclass(frozen=True)
class Figure:
    """A figure of the campaign's HTML report.

    kind "sweep": the metrics ``y`` of ``cases`` against their ``params[x]`` (one panel per
    metric); kind "timeseries": timeseries.csv ``column`` of both sides of each case.
    """

    name: str
    title: str
    kind: str
    cases: tuple[str, ...]
    x: str = ""
    y: tuple[str, ...] = ()
    column: str = ""
    logx: bool = False
    logy: bool | tuple[bool, ...] = False  # one for all panels, or one per metric of y
    reference_slope: float | None = None  # draw a line of this slope (log-log convergence order)
    exact: dict[str, float] = field(default_factory=dict)  # metric -> exact value, drawn as a line
    param2: str = ""  # "heatmap" / "cuts": the second parameter (the y axis of the heatmap)
    instants: tuple[tuple[str, str], ...] = ()  # "maps": (label, "13%" | "peak-load") per map


@dataclass(frozen=True)
class Analysis:
    """A campaign-level result over several cases, computed after them (verification.analyses).

    kind "order": observed convergence orders of ``settings["metric"]`` against the cases'
    ``params[settings["x"]]`` (mode "vs-exact" or "richardson"), judged when ``min_order`` is
    given; kind "thesis": rows of our numbers beside the thesis's, flagged beyond ``flag_rel``;
    kind "sensitivity": relative changes of a metric over a two-parameter grid against the thesis's;
    kind "table": one row per case, one column per metric (e.g. DEM vs FE at five instants).
    """

    name: str
    title: str
    kind: str
    cases: tuple[str, ...]
    settings: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Campaign:
    name: str
    description: str
    cases: tuple[Case, ...]
    figures: tuple[Figure, ...] = ()
    analyses: tuple[Analysis, ...] = ()

    def case(self, name: str) -> Case:
        for case in self.cases:
            if case.name == name:
                return case
        raise KeyError(name)


# ---------------------------------------------------------------------------------------------
# Building blocks


def _tol(value: float, names: tuple[str, ...] = SPEC8_METRICS) -> dict[str, float]:
    return {name: value for name in names}


def ramp_overrides(n_steps: int, force_n: float, duration_s: float = 1.0) -> dict[str, Any]:
    """load.time_s and load.force_n for a linear ramp 0 -> force_n along z in n_steps equal increments."""
    times = [duration_s * k / n_steps for k in range(n_steps + 1)]
    forces = [[0.0, 0.0, force_n * k / n_steps] for k in range(n_steps + 1)]
    return {"load.time_s": times, "load.force_n": forces}


PLATES = "flat-plates.toml"  # 20 x 20 mm, gap 2 mm, E 10.35 MPa, nu 0.42, threshold, 400 N
PLATE_AREA_MM2 = 400.0
LOG_LAW_FORCE_N = 10_000.0
LOG_LAW_STEPS = (4, 8, 16, 32, 64, 128)
HEMISPHERE_LEVELS = (1, 2, 3, 4, 5, 6)
STABILITY_CHECKS = ("outcome_mismatch", "non_finite_outputs", "force_residual_rel")
STABILITY_TOL = {"outcome_mismatch": 0.0, "non_finite_outputs": 0.0, "force_residual_rel": 1e-8}


def _analytic_cases() -> list[Case]:
    cases = [
        Case(
            "flat-plates-dem",
            "DEM, parallel plates 2 mm apart, 400 N: p = F/A, d = F h/(E' A)",
            PLATES,
            ("dem", "closed-form:flat-plates"),
            SPEC8_METRICS,
            _tol(1e-9),
        ),
        Case(
            "flat-plates-edem",
            "EDEM (one step from the initial pose) on the same plates: same closed form",
            PLATES,
            ("edem", "closed-form:flat-plates"),
            SPEC8_METRICS,
            _tol(1e-9),
        ),
        Case(
            "flat-plates-dem-series",
            "DEM over 100, 200, 400 N (each time point static): p = F/A, d = F h/(E' A) per point",
            PLATES,
            ("dem", "closed-form:flat-plates"),
            SPEC8_METRICS,
            _tol(1e-9),
            overrides={"load.time_s": [0.0, 1.0, 2.0], "load.force_n": [[0.0, 0.0, 100.0], [0.0, 0.0, 200.0], [0.0, 0.0, 400.0]]},
        ),
        Case(
            "tilted-plane-dem",
            "DEM, plate under a plane tilted 3 deg, rotations fixed: p(x) = E' d / h(x) (midpoint-rule O(dx^2) from the integral)",
            "tilted-plane.toml",
            ("dem", "closed-form:tilted-plane"),
            SPEC8_METRICS,
            _tol(1e-3),
        ),
        Case(
            "cylinder-plane-dem",
            "DEM, cylinder R 20 mm under a plane (mesh 0.94 mm): discrete foundation p = E' d cos(phi)/h(phi); "
            "L2 dominated by the faceted candidate boundary",
            "cylinder-plane.toml",
            ("dem", "closed-form:cylinder-plane"),
            SPEC8_METRICS,
            {**_tol(0.01), "pressure_l2_rel_error": 0.05},
            params={"mesh_size_mm": 0.94},
        ),
        Case(
            "cylinder-plane-dem-fine",
            "the same cylinder meshed at 0.47 mm: the faceting errors shrink",
            "cylinder-plane.toml",
            ("dem", "closed-form:cylinder-plane"),
            SPEC8_METRICS,
            {**_tol(0.002), "pressure_l2_rel_error": 0.005},
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


def _stability_cases() -> list[Case]:
    converges, closed = Expect("converges"), ("dem", "closed-form:flat-plates")
    plate_checks = STABILITY_CHECKS + ("peak_pressure_rel_error", "displacement_rel_error")
    plate_tol = {**STABILITY_TOL, "peak_pressure_rel_error": 1e-8, "displacement_rel_error": 1e-8}

    def refused(pattern: str) -> Expect:
        return Expect("refused", pattern)

    cases = []
    for nu in (0.49, 0.499, 0.4999):
        cases.append(Case(f"nu-{nu:g}", f"nearly incompressible, nu = {nu:g} (E' = {confined_modulus_mpa(10.35, nu):.4g} MPa)", PLATES, closed, plate_checks, plate_tol, {"cartilage.poissons_ratio": nu}, converges))
    # Linear springs solve any load, but an approach beyond the spring length (d = F h / (E' A) > h)
    # is outside the model's range: the run must say so, and refuse an approach beyond the ray
    # window h_max = 3.5 mm (edem.consistency: the pose leaves the measured geometry).
    past_length = Expect("converges", warning=r"compressed past their length")

    def plate_outcome(force_n: float, youngs_modulus_mpa: float) -> Expect:
        approach_mm = force_n * 2.0 / (confined_modulus_mpa(youngs_modulus_mpa, 0.42) * PLATE_AREA_MM2)
        return refused(r"ray window") if approach_mm > 3.5 else past_length if approach_mm >= 2.0 else converges

    def plate_case(name: str, description: str, overrides: dict[str, Any], expect: Expect) -> Case:
        if expect.outcome == "refused":  # no result to hold against the closed form
            return Case(name, description, PLATES, ("dem",), STABILITY_CHECKS, STABILITY_TOL, overrides, expect)
        return Case(name, description, PLATES, closed, plate_checks, plate_tol, overrides, expect)

    for e in (0.01, 1e4):
        cases.append(plate_case(f"E-{e:g}", f"Young's modulus {e:g} MPa", {"cartilage.youngs_modulus_mpa": e}, plate_outcome(400.0, e)))
    for f in (0.0, 1e-6, 15000.0, 1e5):  # 15 kN: d = 2.8 mm, past h = 2 mm inside the window
        cases.append(plate_case(f"load-{f:g}", f"normal load {f:g} N (linear springs, d = F h / (E' A))", {"load.force_n": [0.0, 0.0, f]}, plate_outcome(f, 10.35)))
    cases += [
        Case(
            "load-1e5-gap-log",
            "1e5 N on the Blankevoort gap-log law (t = 2.5 mm): the springs stiffen, never pass t",
            PLATES,
            ("dem",),
            STABILITY_CHECKS,
            STABILITY_TOL,
            {"load.force_n": [0.0, 0.0, 1e5], "cartilage.law": "gap-log", "cartilage.thickness_mm": 2.5},
            converges,
        ),
        Case("pull-apart", "a load pulling the plates apart (-100 N)", PLATES, ("dem",), STABILITY_CHECKS, STABILITY_TOL, {"load.force_n": [0.0, 0.0, -100.0]}, refused(r"no equilibrium")),
        Case(
            "tangential-no-shear",
            "tangential load, tx free, zero shear stiffness: singular, names tx",
            PLATES,
            ("dem",),
            STABILITY_CHECKS,
            STABILITY_TOL,
            {"load.force_n": [10.0, 0.0, 100.0], "constraints.fixed_dofs": ["ty", "rx", "ry", "rz"]},
            refused(r"nothing resists motion along tx"),
        ),
        Case(
            "tangential-with-shear",
            "the same tangential load with shear stiffness G = 1 MPa",
            PLATES,
            ("dem",),
            STABILITY_CHECKS,
            STABILITY_TOL,
            {"load.force_n": [10.0, 0.0, 100.0], "constraints.fixed_dofs": ["ty", "rx", "ry", "rz"], "cartilage.shear_modulus_mpa": 1.0},
            converges,
        ),
        Case("hmax-0.1-touching", "h_max = 0.1 mm, plates 0.05 mm apart", PLATES, closed, plate_checks, plate_tol, {"cartilage.max_spring_length_mm": 0.1, "geometry.gap_mm": 0.05}, converges),
        Case("hmax-0.1-apart", "h_max = 0.1 mm, plates 2 mm apart: no candidate", PLATES, ("dem",), STABILITY_CHECKS, STABILITY_TOL, {"cartilage.max_spring_length_mm": 0.1}, refused(r"no spring is a candidate")),
        Case("far-apart-10mm", "plates 10 mm apart, h_max 3.5 mm: no candidate", PLATES, ("dem",), STABILITY_CHECKS, STABILITY_TOL, {"geometry.gap_mm": 10.0}, refused(r"no spring is a candidate")),
        Case("far-apart-1m", "plates 1000 mm apart (a unit mismatch)", PLATES, ("dem",), STABILITY_CHECKS, STABILITY_TOL, {"geometry.gap_mm": 1000.0}, refused(r"bodies too far apart")),
        Case(
            "interpenetrating-start",
            "the plane turned 30 deg about an axis 5 mm below the plate cuts through it (threshold law)",
            PLATES,
            ("dem",),
            STABILITY_CHECKS,
            STABILITY_TOL,
            {"kinematics.axis_point_mm": [0.0, 0.0, -5.0], "kinematics.axis_direction": [1.0, 0.0, 0.0], "kinematics.angle_deg": -30.0},
            refused(r"compressed past their length"),
        ),
        Case(
            "compressed-past-length-edem",
            "EDEM, one increment compresses the springs 3 mm (> h = 2 mm): the next step refuses",
            PLATES,
            ("edem",),
            STABILITY_CHECKS,
            STABILITY_TOL,
            {"load.time_s": [0.0, 1.0, 2.0], "load.force_n": [[0.0, 0.0, 1.0], [0.0, 0.0, 3.0 * confined_modulus_mpa(10.35, 0.42) * PLATE_AREA_MM2 / 2.0], [0.0, 0.0, 16000.0]]},
            refused(r"compressed past their length"),
        ),
    ]
    cylinder = "cylinder-plane.toml"  # the idealised talus (3046 springs) under a plane, 333 N
    cases += [
        Case(
            "cylinder-nu-0.4999",
            "cylinder under a plane, nu = 0.4999: still the discrete foundation solution",
            cylinder,
            ("dem", "closed-form:cylinder-plane"),
            STABILITY_CHECKS + ("peak_pressure_rel_error", "displacement_rel_error"),
            {**STABILITY_TOL, "peak_pressure_rel_error": 0.01, "displacement_rel_error": 0.01},
            {"cartilage.poissons_ratio": 0.4999},
            converges,
        ),
        Case(
            "cylinder-axial-no-shear",
            "cylinder, 10 N along the axis with tx free and no shear stiffness: refused (faceting leaves the axis a "
            "tiny normal stiffness, so the refusal is 'no equilibrium' rather than naming tx)",
            cylinder,
            ("dem",),
            STABILITY_CHECKS,
            STABILITY_TOL,
            {"load.force_n": [10.0, 0.0, 333.0], "constraints.fixed_dofs": ["ty", "rx", "ry", "rz"]},
            refused(r"nothing resists motion along tx|no equilibrium"),
        ),
    ]
    # Kelvin-Voigt springs over tau x dt (SPEC 4): ramp to 300 N in 3 steps, hold 2 steps.
    # exact integrator: converges everywhere, pressure = F/A at every time point (it follows the
    # load); RK2: converges for dt <= 2 tau, refused beyond.
    for tau in (1e-4, 1e-2, 1.0, 1e2, 1e4):
        for dt in (1e-3, 1e-1, 1.0):
            ramp = {
                "load.time_s": [k * dt for k in range(6)],
                "load.force_n": [[0.0, 0.0, 100.0 * min(k, 3)] for k in range(6)],
                "viscoelastic.relaxation_time_s": tau,
            }
            for integrator in ("exact", "rk2"):
                stable = integrator == "exact" or dt <= 2.0 * tau
                cases.append(
                    Case(
                        f"ve-{integrator}-tau{tau:.0e}-dt{dt:.0e}",
                        f"viscoelastic EDEM, {integrator}, tau = {tau:g} s, dt = {dt:g} s (dt/tau = {dt / tau:.3g})",
                        PLATES,
                        ("edem", "closed-form:flat-plates"),
                        STABILITY_CHECKS + ("peak_pressure_rel_error", "pressure_l2_rel_error"),
                        {**STABILITY_TOL, "peak_pressure_rel_error": 1e-9, "pressure_l2_rel_error": 1e-9},
                        {**ramp, "viscoelastic.integrator": integrator},
                        converges if stable else refused(r"RK2 is unstable"),
                    )
                )
    return cases


def _ideal_standing_case() -> Case:
    return Case(
        "ideal-standing-edem-vs-dem",
        "ideal standing (333 N): EDEM's first step starts from the initial pose, so it equals DEM",
        "ideal-standing",
        ("edem", "dem"),
        SPEC8_METRICS,
        _tol(1e-9),
        maps=True,
    )


# ---------------------------------------------------------------------------------------------
# fe-analytic: the FE reference against its closed forms (SPEC 5), three meshes each

HERTZ_SIZES_MM = (0.4, 0.2, 0.1)  # contact element size = slice thickness; far size 10x (ratio 2)
CONFINED_SIZES_MM = (2.0, 1.0, 0.5)  # slab 10 x 8 x 2 mm: (5, 4, 1), (10, 8, 2), (20, 16, 4) boxes
HERTZ_METRICS = ("peak_pressure_rel_error", "half_width_rel_error", "half_width_fit_rel_error", "mean_pressure_rel_error", "pressure_l2_rel_error", "a_displacement_norm_mm")
CONFINED_METRICS = SPEC8_METRICS


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
                # tests/fem_reference/test_fe_confined_compression.py: pressure, peak and d within 1 %, area 1e-9
                {"peak_pressure_rel_error": 0.01, "mean_pressure_rel_error": 0.01, "displacement_rel_error": 0.01, "pressure_l2_rel_error": 0.01, "contact_area_rel_error": 1e-9},
                options={"mesh_size_mm": size, "element": "P2"},
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


def fe_analytic_campaign() -> Campaign:
    return Campaign(
        "fe-analytic",
        "The FE reference (fem_reference core, P2) against closed forms: Hertz line contact (peak pressure, half-width) and confined compression (p = E' d / h), three meshes each, with observed orders.",
        tuple(_fe_analytic_cases()),
        _fe_analytic_figures(),
        _fe_analytic_analyses(),
    )


# ---------------------------------------------------------------------------------------------
# stance: EDEM vs DEM over the built-in stance scenes (SPEC 7, thesis 4.3.4)

STANCE_SCENES = ("ideal-stance", "subject-stance")
#: the instants of the pressure maps (and of the FE solves): label, % of stance or "peak-load"
STANCE_INSTANTS = (("heel strike", "0%"), ("foot flat", "13%"), ("mid-stance", "50%"), ("peak load", "peak-load"), ("toe off", "100%"))
STANCE_SERIES = tuple(f"{side}_{name}" for side in "ab" for name in ("peak_pressure_mpa", "mean_contact_area_mm2", "max_superior_displacement_mm", "max_superior_displacement_percent"))
#: SPEC 7: the thesis's EDEM stance (4.3.4), for qualitative comparison
THESIS_STANCE = {"superior_displacement_mm": 0.57, "superior_displacement_percent": 80.0, "mean_area_edem_cm2": 4.67, "mean_area_dem_cm2": 4.18, "peak_edem_mpa": 7.3, "peak_dem_mpa": 6.92}
THESIS_FLAG_REL = 0.25  # flag ours against the thesis's beyond +-25 %


def instant_indices(time_s: Any, force_n: Any, instants: tuple[tuple[str, str], ...] = STANCE_INSTANTS) -> list[int]:
    """Time-point index of each instant: the nearest to "<p>%" of the time span, or the largest |F| ("peak-load")."""
    import numpy as np

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
    import tomllib

    from edem.scene import resolve_scene_path

    load = tomllib.loads(resolve_scene_path(scene).read_text(encoding="utf-8"))["load"]
    return instant_indices(load["time_s"], load["force_n"], instants)


def _slug(text: str) -> str:
    return "-".join(text.lower().split())


FE_INSTANT_METRICS = SPEC8_METRICS + (
    "a_at_b_peak_pressure_mpa",
    "b_peak_pressure_mpa",
    "a_at_b_mean_contact_area_mm2",
    "b_mean_contact_area_mm2",
    "a_at_b_displacement_norm_mm",
    "b_displacement_norm_mm",
)


def fe_instant_case_name(scene: str, label: str) -> str:
    return f"{scene}-fe-{_slug(label)}"


def _stance_cases() -> list[Case]:
    cases = []
    for scene in STANCE_SCENES:
        cases.append(
            Case(
                f"{scene}-edem-vs-dem",
                f"{scene}: EDEM (incremental, push-back) against DEM (each time point static), 65 time points; no tolerance: the methods differ by design",
                scene,
                ("edem", "dem"),
                SPEC8_METRICS + STANCE_SERIES + ("outcome_mismatch",),
                {"outcome_mismatch": 0.0},  # EDEM must solve the whole stance
                expect=Expect("converges"),
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
    """Overrides of the DEM-vs-FE cases: no ligaments (the FE models none), STANCE_FE_FIXED added
    to the scene's own fixed DOFs."""
    import tomllib

    from edem.scene import resolve_scene_path

    overrides: dict[str, Any] = {"ligaments": []}
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
        {"header": "DEM peak (MPa)", "metric": "a_at_b_peak_pressure_mpa"},
        {"header": "FE peak (MPa)", "metric": "b_peak_pressure_mpa"},
        {"header": "peak rel. error", "metric": "peak_pressure_rel_error"},
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
            "Stance: our runs beside the thesis's figures (SPEC 7; thesis EDEM stance 4.3.4). Reported, no verdict; flagged beyond +-25 %",
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


def stance_campaign() -> Campaign:
    return Campaign(
        "stance",
        "EDEM vs DEM over the built-in ideal and subject stances (65 time points): displacement, peak pressure and contact area over time, pressure maps at five instants, "
        "the thesis's figures beside ours, and the FE slab at those instants when fem_reference.run_scene exists.",
        tuple(_stance_cases()),
        _stance_figures(),
        _stance_analyses(),
    )


# ---------------------------------------------------------------------------------------------
# sensitivity: h_max x ligament modulus over the ideal stance (thesis fig. 4.3.10)

SENSITIVITY_SCENE = "ideal-stance"
SENSITIVITY_GRID = 20
SENSITIVITY_HMAX_MM = (2.5, 4.5)
SENSITIVITY_MODULUS_MPA = (200.0, 350.0)
THESIS_SENSITIVITY = {"hmax_change": -0.30, "modulus_change": 0.03}  # SPEC 7: peak -30 % from h_max 2.5 to 4.5; ~3 % over the moduli


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
                    f"EDEM ideal stance, h_max {h:.4g} mm, ligament modulus {e:.4g} MPa (all four ligaments)",
                    SENSITIVITY_SCENE,
                    ("edem",),
                    ("a_peak_pressure_mpa", "a_mean_contact_area_mm2", "outcome_mismatch"),
                    {"outcome_mismatch": 0.0},  # every run of the grid must solve its stance
                    overrides={"cartilage.max_spring_length_mm": h, "ligaments[*].youngs_modulus_mpa": e},
                    expect=Expect("converges"),
                    options={"frames": "peak"},
                    params={"h_max_mm": h, "ligament_modulus_mpa": e},
                )
            )
    return cases


def sensitivity_campaign(n: int = SENSITIVITY_GRID) -> Campaign:
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
                "Relative change of the peak pressure across each parameter's range, beside the thesis's (SPEC 7); reported, no verdict",
                "sensitivity",
                names,
                {"x": "h_max_mm", "y": "ligament_modulus_mpa", "metric": "a_peak_pressure_mpa", "thesis_x_change": THESIS_SENSITIVITY["hmax_change"], "thesis_y_change": THESIS_SENSITIVITY["modulus_change"], "flag_rel": THESIS_FLAG_REL},
            ),
        ),
    )


def _quick() -> Campaign:
    stability = {c.name: c for c in _stability_cases()}
    picks = ["nu-0.4999", "load-0", "pull-apart", "tangential-no-shear", "interpenetrating-start", "cylinder-axial-no-shear", "ve-exact-tau1e-04-dt1e+00", "ve-rk2-tau1e-04-dt1e+00"]
    fe = {c.name: c for c in _fe_analytic_cases()}
    # one cheap FE case (a second or two; "unavailable" without dolfinx): the coarsest confined slab
    fe_picks = [f"fe-confined-compression-h{max(CONFINED_SIZES_MM):g}"]
    return Campaign(
        "quick",
        "A CI subset (well under 5 minutes on 2 cores): every closed-form case, a few stability cases, ideal standing EDEM vs DEM, one cheap FE case (confined compression, coarse).",
        tuple(_analytic_cases()) + tuple(stability[n] for n in picks) + (_ideal_standing_case(),) + tuple(fe[n] for n in fe_picks),
        _analytic_figures(),
    )


def campaigns() -> dict[str, Campaign]:
    """Every campaign by name."""
    return {
        "edem-analytic": Campaign(
            "edem-analytic",
            "EDEM/DEM against closed forms: flat plates, tilted plane, cylinder on a plane, the log law under a ramp, hemisphere thickness convergence.",
            tuple(_analytic_cases()),
            _analytic_figures(),
        ),
        "stability": Campaign(
            "stability",
            "Stiff and extreme input: each case ends in its declared outcome (converges with a small residual, or refused with a clear message) and no output holds a NaN.",
            tuple(_stability_cases()),
        ),
        "fe-analytic": fe_analytic_campaign(),
        "stance": stance_campaign(),
        "sensitivity": sensitivity_campaign(),
        "quick": _quick(),
        **_fe_campaigns(),
    }


def _fe_campaigns() -> dict[str, Campaign]:
    """cylinder-plane, subject and error-vs-runtime (verification.fe_campaigns): EDEM/DEM vs the FE reference."""
    from verification.fe_campaigns import fe_campaigns

    return fe_campaigns()


def get_campaign(name: str) -> Campaign:
    """The named campaign, or InputError listing the known ones."""
    known = campaigns()
    if name not in known:
        raise InputError(f"unknown campaign '{name}'", key="CAMPAIGN", expected="one of " + ", ".join(known) + " (edem verify --list)")
    return known[name]


def validate_campaign(campaign: Campaign) -> None:
    """InputError when a case names an unknown side or metric, or a tolerance on an unreported metric."""
    from verification.sides import check_side

    seen = set()
    for case in campaign.cases:
        key = f"{campaign.name}.{case.name}"
        if case.name in seen:
            raise InputError(f"duplicate case name '{case.name}'", key=key, expected="unique case names")
        seen.add(case.name)
        if not 1 <= len(case.sides) <= 2:
            raise InputError(f"{len(case.sides)} sides", key=key, expected="one or two sides")
        for side in case.sides:
            check_side(side)
        unknown = [m for m in case.metrics if m not in METRICS]
        if unknown:
            raise InputError(f"unknown metric(s) {', '.join(unknown)}", key=key, expected="metrics of verification.campaigns.METRICS")
        stray = [m for m in case.tolerance if m not in case.metrics]
        if stray:
            raise InputError(f"tolerance on unreported metric(s) {', '.join(stray)}", key=key, expected="tolerances on the case's own metrics")
        if any(not isinstance(v, (int, float)) or math.isnan(v) for v in case.tolerance.values()):
            raise InputError("tolerances must be numbers", key=key, expected="metric -> max value")
    for figure in campaign.figures:
        missing = [c for c in figure.cases if c not in seen]
        if missing:
            raise InputError(f"figure '{figure.name}' names unknown case(s) {', '.join(missing)}", key=campaign.name)
    from verification.analyses import ANALYSES

    for analysis in campaign.analyses:
        missing = [c for c in analysis.cases if c not in seen]
        if missing:
            raise InputError(f"analysis '{analysis.name}' names unknown case(s) {', '.join(missing)}", key=campaign.name)
        if analysis.kind not in ANALYSES:
            raise InputError(f"analysis '{analysis.name}' of unknown kind {analysis.kind!r}", key=campaign.name, expected="one of " + ", ".join(ANALYSES))


def describe_campaigns() -> str:
    """What `edem verify --list` prints: each campaign, then one line per case."""
    lines = []
    for campaign in campaigns().values():
        lines.append(f"{campaign.name} ({len(campaign.cases)} cases): {campaign.description}")
        for case in campaign.cases:
            versus = " vs ".join(case.sides)
            lines.append(f"  {case.name:32s} [{versus}] {case.description}")
        lines.append("")
    return "\n".join(lines).rstrip() + "\n"


# The FE comparison campaigns register two truth sides and the "pareto" analysis kind: import the
# module here (at the end, once every name above exists) so spawned workers see them too.
import verification.fe_campaigns  # noqa: E402,F401
