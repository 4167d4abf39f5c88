"""The campaign data model (docs/campaigns.md, docs/method.md#7-comparison-metrics): cases, figures, analyses, campaigns and their validation.

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

The campaigns themselves are modules of :mod:`verification.campaigns`, one per campaign.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from edem.beds import CoupledThinLayer, IndependentSprings
from geometries.errors import InputError
from verification.analyses import ANALYSES
from verification.bed_compliance import BED_COMPLIANCE_DESCRIPTIONS
from verification.fe_convergence import FE_VALUE_DESCRIPTIONS
from verification.metrics import COMPARISON_METRICS, COP_METRICS, SERIES_METRICS
from verification.sides import check_side
from verification.verdicts import Basis, bases_for

SCENES_DIR = Path(__file__).resolve().parent / "scenes"

#: every metric a case may report, with what it measures
METRICS: dict[str, str] = {
    "regularised_peak_pressure_rel_error": "(peak_a - peak_b) / peak_b of the regularised peak (the pressure's largest mean over 1 mm^2, "
                                           "edem.pressure_metrics; the largest magnitude over compared time points, signed), docs/method.md#7-comparison-metrics",
    "peak_pressure_rel_error": "(peak_a - peak_b) / peak_b of the raw peak (largest nodal or spring pressure: mesh-dependent, reported only), docs/method.md#7-comparison-metrics",
    "mean_pressure_rel_error": "signed relative error of the mean pressure (contact force / contact area), docs/method.md#7-comparison-metrics",
    "contact_area_rel_error": "signed relative error of the contact area, docs/method.md#7-comparison-metrics",
    "displacement_rel_error": "|u_a - u_b| / |u_b| of the bone displacement, negative when a moves less than b, docs/method.md#7-comparison-metrics",
    "pressure_l2_rel_error": "area-weighted L2 relative error of the pressure at a's spring centroids, docs/method.md#7-comparison-metrics",
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
    "regularised_peak_pressure_mpa": "largest regularised peak pressure (mean over 1 mm^2, edem.pressure_metrics) over the time points",
    "peak_pressure_mpa": "largest raw peak pressure over the time points (mesh-dependent, reported only)",
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

#: side a's values at side b's time points beside b's own: regularised and raw peak pressure, mean area, |u|
VALUES_AT_REFERENCE_TIMES = (
    "a_at_b_regularised_peak_pressure_mpa",
    "b_regularised_peak_pressure_mpa",
    "a_at_b_peak_pressure_mpa",
    "b_peak_pressure_mpa",
    "a_at_b_mean_contact_area_mm2",
    "b_mean_contact_area_mm2",
    "a_at_b_displacement_norm_mm",
    "b_displacement_norm_mm",
)

METRICS.update(COP_METRICS)
METRICS.update(FE_VALUE_DESCRIPTIONS)
METRICS.update(BED_COMPLIANCE_DESCRIPTIONS)

#: the beds a case can pin with its overrides (``[cartilage] coupling``, edem.beds.BEDS). The
#: built-in ankle scenes default to the coupled thin layer (Pade symbol); a case that compares a
#: thesis figure, or the independent springs as such, names its bed instead of taking the default.
THESIS_BED = {"cartilage.coupling": IndependentSprings.coupling}  # the thesis's independent springs
COUPLED_BED = {"cartilage.coupling": CoupledThinLayer.coupling, "cartilage.thin_layer_symbol": "pade"}
#: the thesis's idealised ankle (docs/method.md#8-built-in-geometries): its geometry without
#: cartilage and its threshold law, whose contact area is the ray window's. The built-in ankle
#: scenes default to the gap law on talar and tibial cartilage measured to the builder's bones; a
#: case that compares a thesis figure, or DEM with the FE slab (the threshold law's twin; the FE
#: has no twin of the two measured layers yet), names this instead of taking the default.
THESIS_ANKLE = {"geometry.cartilage": False, "cartilage.law": "threshold"}

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
    options: dict[str, Any] = field(default_factory=dict)  # side options (FE: verification.sides.FE_SCENE_OPTIONS, steps)
    params: dict[str, float] = field(default_factory=dict)  # x values for the report's figures
    maps: bool = False  # render pressure maps of a against b in the report
    #: why each tolerance has its value (verification.verdicts.Basis), beyond the standard ones
    #: (verification.verdicts.STANDARD_BASES); validate_campaign refuses a tolerance without one
    basis: dict[str, Basis] = field(default_factory=dict)
    #: the FE reference's estimated relative error per metric (metric -> error >= 0, e.g. a
    #: Richardson estimate of its mesh study): a model band not larger than it judges nothing
    #: (verification.verdicts.tolerance_verdicts, "FE not converged enough to judge")
    fe_errors: dict[str, float] = field(default_factory=dict)

    def bases(self) -> dict[str, Basis]:
        """The basis of every tolerance (the case's own, then the standard ones)."""
        return bases_for(self.tolerance, self.basis)

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
    metric); kind "scatter": the same as unjoined points (a population); kind "histogram": the
    distribution of each metric of ``y`` over the cases (a "sweep" may split its cases into
    labelled ``series``, one line each); kind "timeseries": timeseries.csv
    ``column`` of both sides of each case; kinds "area-vs-load" and "per-load", for cases
    against the FE at several loads (their time points): the contact area of both sides against
    the load, and each comparison metric of ``y`` against the load, one line per ``series``.
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
    #: "sweep": (label, cases) drawn as separate lines on every panel (e.g. two models); cases holds them all
    series: tuple[tuple[str, tuple[str, ...]], ...] = ()
    lines: tuple[tuple[str, float, str], ...] = ()  # "sweep": horizontal lines (metric, value, label) on that metric's panel, e.g. a goal


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
    #: wall time of a full run with 2 jobs on 2 cores, no cache (docs/campaigns.md says how measured)
    expected_time_s: float | None = None

    def case(self, name: str) -> Case:
        for case in self.cases:
            if case.name == name:
                return case
        raise KeyError(name)


def uniform_tolerance(value: float, names: tuple[str, ...] = COMPARISON_METRICS) -> dict[str, float]:
    """The same largest admissible value for every metric of ``names``."""
    return {name: value for name in names}


def uniform_basis(kind: str, reason: str, names: tuple[str, ...] = COMPARISON_METRICS) -> dict[str, Basis]:
    """The same :class:`Basis` for every metric of ``names``."""
    basis = Basis(kind, reason)
    return {name: basis for name in names}


def ramp_overrides(n_steps: int, force_n: float, duration_s: float = 1.0) -> dict[str, Any]:
    """load.time_s and load.force_n for a linear ramp 0 -> force_n along z in n_steps equal increments."""
    times = [duration_s * k / n_steps for k in range(n_steps + 1)]
    forces = [[0.0, 0.0, force_n * k / n_steps] for k in range(n_steps + 1)]
    return {"load.time_s": times, "load.force_n": forces}


def validate_campaign(campaign: Campaign) -> None:
    """InputError when a case names an unknown side or metric, or a tolerance on an unreported metric."""
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
            raise InputError(f"unknown metric(s) {', '.join(unknown)}", key=key, expected="metrics of verification.campaign_model.METRICS")
        stray = [m for m in case.tolerance if m not in case.metrics]
        if stray:
            raise InputError(f"tolerance on unreported metric(s) {', '.join(stray)}", key=key, expected="tolerances on the case's own metrics")
        try:
            case.bases()
        except KeyError as exc:
            raise InputError(f"tolerance without a stated reason: {exc.args[0]}", key=key, expected="a verification.verdicts.Basis per tolerance (Case.basis)") from None
        if any(not isinstance(v, (int, float)) or math.isnan(v) for v in case.tolerance.values()):
            raise InputError("tolerances must be numbers", key=key, expected="metric -> max value")
    for figure in campaign.figures:
        missing = [c for c in figure.cases if c not in seen]
        if missing:
            raise InputError(f"figure '{figure.name}' names unknown case(s) {', '.join(missing)}", key=campaign.name)
    for analysis in campaign.analyses:
        missing = [c for c in analysis.cases if c not in seen]
        if missing:
            raise InputError(f"analysis '{analysis.name}' names unknown case(s) {', '.join(missing)}", key=campaign.name)
        if analysis.kind not in ANALYSES:
            raise InputError(f"analysis '{analysis.name}' of unknown kind {analysis.kind!r}", key=campaign.name, expected="one of " + ", ".join(ANALYSES))
