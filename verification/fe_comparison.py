"""A discrete side against the FE reference: the case, its metrics and tolerances, and the columns
of its tables, shared by every campaign that compares DEM / EDEM with the FE (cylinder-plane,
subject, error-vs-runtime, thin-layer, viscoelastic, fe-convergence, real-knee, quick).

The tolerances are generous: such a case measures the model gap and fails only when something is
broken (a NaN, a force residual, an error beyond 1000 %); a campaign that judges the gap against a
goal states its own band (docs/campaigns.md#verdicts). Every table beside the errors gives the FE
reference's own estimated error from the fe-convergence study
(:func:`verification.fe_convergence.fe_error_text`), since a model error below it cannot be told
from the reference's.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from verification.bed_compliance import BED_COMPLIANCE_METRICS
from verification.campaign_model import VALUES_AT_REFERENCE_TIMES, Case, uniform_basis
from verification.fe_convergence import FE_ERROR_TEXT_METRICS
from verification.metrics import COMPARISON_METRICS
from verification.verdicts import INVARIANT, MODEL_BAND, MODEL_BAND_REASON, MODEL_BAND_REL, SANITY, Basis

FE_COARSE = {"mesh_size_mm": 1.0, "degree": 2}  # P2 at 1.0 mm; Taylor-Hood (auto) from nu = 0.49
CHECK_METRICS = ("force_residual_rel", "non_finite_outputs")
FE_COMPARE_METRICS = COMPARISON_METRICS + VALUES_AT_REFERENCE_TIMES + CHECK_METRICS
#: generous: a relative error beyond 10 (1000 %) or a NaN means something is broken, not a model gap
FE_COMPARE_TOL = {**{m: 10.0 for m in COMPARISON_METRICS}, "force_residual_rel": 1e-6, "non_finite_outputs": 0.0}
#: why: these bounds catch a broken run only, so such a case "ran" (its errors are reported, not judged)
SANITY_BASIS = uniform_basis(SANITY, "1000 %: catches a broken run (a wrong load, a lost contact), not a model gap; the errors are reported, not judged")
FE_COMPARE_BASIS = {**SANITY_BASIS, "force_residual_rel": Basis(INVARIANT, "equilibrium of the discrete side, 1e-6 of the load")}
ERROR_PANELS = ("regularised_peak_pressure_rel_error", "contact_area_rel_error", "displacement_rel_error", "pressure_l2_rel_error")
#: the FE reference's own estimated error (verification.fe_convergence; "unknown" when its run is
#: not in the fe-convergence study): a model error below it cannot be told from the reference's
FE_ERROR_COLUMNS = [{"header": header, "fe_error": metric}
                    for header, metric in zip(("FE's own err: regularised peak", "area", "|u|", "L2"), FE_ERROR_TEXT_METRICS, strict=True)]
#: the table columns of DEM against the FE: values of both sides and the errors
FE_VALUE_COLUMNS = [
    {"header": "DEM regularised peak (MPa)", "metric": "a_at_b_regularised_peak_pressure_mpa"},
    {"header": "FE regularised peak (MPa)", "metric": "b_regularised_peak_pressure_mpa"},
    {"header": "regularised peak err", "metric": "regularised_peak_pressure_rel_error"},
    {"header": "raw peak err (reported only)", "metric": "peak_pressure_rel_error"},
    {"header": "DEM area (mm^2)", "metric": "a_at_b_mean_contact_area_mm2"},
    {"header": "FE area (mm^2)", "metric": "b_mean_contact_area_mm2"},
    {"header": "area err", "metric": "contact_area_rel_error"},
    {"header": "DEM |u| (mm)", "metric": "a_at_b_displacement_norm_mm"},
    {"header": "FE |u| (mm)", "metric": "b_displacement_norm_mm"},
    {"header": "disp err", "metric": "displacement_rel_error"},
    {"header": "L2 err", "metric": "pressure_l2_rel_error"},
]
#: ... and the FE reference's own error, from the fe-convergence study
FE_TABLE_COLUMNS = [*FE_VALUE_COLUMNS, *FE_ERROR_COLUMNS]


def fe_comparison_case(name: str, description: str, scene: str, sides: tuple[str, ...], *, overrides: dict[str, Any],
                       options: dict[str, Any], maps: bool, params: dict[str, float] | None = None) -> Case:
    """A discrete side against the FE with this module's metrics, generous tolerances and their basis."""
    return Case(name, description, scene, sides, FE_COMPARE_METRICS, dict(FE_COMPARE_TOL), overrides=overrides,
                options=dict(options), params=params or {}, maps=maps, basis=dict(FE_COMPARE_BASIS))


#: the design card's three quantities, each judged against the declared model band: pressure (the
#: regularised peak and the field's L2 error), contact area and talus displacement; "verified"
#: needs every one inside (the raw peak and the mean pressure are reported only)
BAND_METRICS = ("regularised_peak_pressure_rel_error", "pressure_l2_rel_error", "contact_area_rel_error", "displacement_rel_error")
BAND_BASIS = Basis(MODEL_BAND, MODEL_BAND_REASON)


def banded(case: Case, area_basis: Basis | None = None) -> Case:
    """A DEM-vs-FE case judged against the model band on the regularised peak, the pressure
    field (L2), the contact area and the displacement (:data:`BAND_METRICS`); the raw peak and
    mean pressure reported (sanity bounds only). ``area_basis``: the area's own basis where the
    law fixes it by construction (judged all the same, its reason says why it does not move)."""
    tolerance = {**case.tolerance, **{m: MODEL_BAND_REL for m in BAND_METRICS}}
    basis = {**case.basis, **{m: BAND_BASIS for m in BAND_METRICS}}
    judged = "regularised peak pressure, pressure field (L2), contact area and displacement"
    if area_basis is not None:
        basis["contact_area_rel_error"] = area_basis
        judged = "regularised peak pressure, pressure field (L2), contact area (set by the threshold law by construction) and displacement"
    description = case.description.replace("Generous tolerances (measured, not judged)", "").replace(". Generous tolerances", "").rstrip(" ;.")
    description += f"; {judged} judged against the declared +-{MODEL_BAND_REL:.0%} model band, the raw peak and mean pressure reported"
    return dataclasses.replace(case, tolerance=tolerance, basis=basis, description=description)


def with_bed_compliance(case: Case) -> Case:
    """A DEM-vs-FE case on a coupled gap-law bed that also reports the bed's deflection under the
    FE's own pressure (:data:`verification.bed_compliance.BED_COMPLIANCE_METRICS`; reported, no tolerance)."""
    return dataclasses.replace(case, metrics=case.metrics + BED_COMPLIANCE_METRICS)
