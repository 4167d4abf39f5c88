"""What a case's verdict means, and why each tolerance has its value (docs/campaigns.md#verdicts).

Every tolerance of a case carries a :class:`Basis`: the kind of claim it checks and, in words,
where its value comes from. The kinds:

* ``closed-form``: a discrete result against its exact solution; the tolerance is round-off or
  the scheme's known discretisation error (its order and size stated).
* ``fe-convergence``: the FE reference against a closed form; the tolerance is the error the
  FE's mesh-convergence study predicts on that mesh.
* ``declared-outcome``: a stability case declared in advance to converge or to be refused with a
  given message; met or not, exactly.
* ``model-band``: two different models (the spring bed against the FE continuum, ours against
  the thesis): a declared band of agreement. Outside it the case is *flagged*, not failed: the
  band marks where the model stops being a good approximation, not a bug.
* ``invariant``: what every run must satisfy (equilibrium to round-off, finite outputs, the run
  solved): necessary, but it verifies no accuracy claim on its own.
* ``by-construction``: a metric the discrete model fixes by construction (the threshold law's
  contact area on the ideal ankle is the candidate springs' area, 463 mm^2 at every load and nu):
  judged against its band exactly as a model band (a fixed value can still be wrong, and
  "verified" needs every card metric inside its band), with the reason saying that the law,
  not the bed's mechanics, sets it;
* ``sanity``: generous bounds that only catch a broken run (an error of 1000 %); meeting them
  verifies nothing: a met sanity bound is "reported, not judged" (grey in the report, never green).

Per tolerance the verdict is "met", "outside band" (a model band exceeded), "fail", "missing",
"n/a" (a case refused as declared), "reported, not judged" (a sanity bound met) or "FE not
converged enough to judge": when the FE reference carries an estimated relative error for the
metric (``fe_errors`` of :func:`tolerance_verdicts`, metric -> relative error, e.g. a Richardson
estimate from its mesh study) and the model band is not larger than that error, the band can judge
nothing. Against an FE reference whose error has not been estimated (its run is not in the
mesh study, ``fe_reference`` without ``fe_errors`` for the metric) a value inside the band is "FE
error unknown": a band can only be met against a reference whose own error is known to be
smaller. Errors are signed ((a - b) / |b|); a band bounds their magnitude.

A case ends as exactly one of :data:`CASE_VERDICTS`:

* ``verified``: every tolerance met, at least one of kind closed-form, fe-convergence,
  declared-outcome (converges) or model-band;
* ``flagged``: everything else met, but a model-band tolerance exceeded;
* ``FE not converged enough to judge``: nothing outside a band, but a model band no wider than
  the FE reference's own estimated error, or an FE reference whose error is unknown (it needs a
  finer FE, or a mesh study, to be judged);
* ``refused as declared``: declared to be refused, and refused with the declared message;
* ``ran``: ran and met its invariants and sanity bounds, but no tolerance makes an accuracy claim
  (its numbers are reported, with no verdict);
* ``failed``: a closed-form, fe-convergence, declared-outcome, invariant or sanity tolerance not
  met (a bug, or a broken run);
* ``error``: a side crashed; ``unavailable``: a side cannot run here (the FE reference missing).

A campaign exits 1 when a case failed or crashed; flagged cases are reported, not failures.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from verification.status import ERROR, FAILED, FE_NOT_CONVERGED, FLAGGED, RAN, REFUSED_AS_DECLARED, UNAVAILABLE, VERIFIED

CLOSED_FORM, FE_CONVERGENCE, DECLARED_OUTCOME, MODEL_BAND, INVARIANT, SANITY, BY_CONSTRUCTION = (
    "closed-form", "fe-convergence", "declared-outcome", "model-band", "invariant", "sanity", "by-construction",
)
BASIS_KINDS = (CLOSED_FORM, FE_CONVERGENCE, DECLARED_OUTCOME, MODEL_BAND, INVARIANT, SANITY, BY_CONSTRUCTION)
#: kinds whose tolerance, once met, makes an accuracy or robustness claim
CLAIM_KINDS = (CLOSED_FORM, FE_CONVERGENCE, DECLARED_OUTCOME, MODEL_BAND)
#: kinds judged as a band between two models: outside it flags, and the FE reference's own error applies
BANDED_KINDS = (MODEL_BAND, BY_CONSTRUCTION)


#: every case verdict, in the order the headline counts them
CASE_VERDICTS = (VERIFIED, FLAGGED, FE_NOT_CONVERGED, REFUSED_AS_DECLARED, RAN, FAILED, ERROR, UNAVAILABLE)
#: per-tolerance verdicts beyond "met", "outside band", "fail", "missing" and "n/a"
NOT_JUDGED = "reported, not judged"
FE_TOO_COARSE = str(FE_NOT_CONVERGED)
FE_ERROR_UNKNOWN = "FE error unknown"
#: what each verdict means, for the report's legend
VERDICT_MEANINGS = {
    VERIFIED: "met every tolerance, including one whose origin is a closed form's discretisation error, an FE mesh-convergence estimate, a declared outcome or a stated model band",
    FLAGGED: "outside a declared model band (against the FE reference or the thesis): a limit of the model, reported",
    FE_NOT_CONVERGED: ("a declared model band no wider than the FE reference's own estimated error for that metric, or an FE reference whose error "
                       "has not been estimated (not in the fe-convergence study): the reference cannot judge it"),
    REFUSED_AS_DECLARED: "declared to be refused (input outside the model) and refused with the declared message",
    RAN: "ran to equilibrium; its numbers are reported with no accuracy verdict",
    FAILED: "missed a tolerance that is not a model band: a bug or a broken run",
    ERROR: "a side crashed",
    UNAVAILABLE: "a side cannot run here (e.g. the FE reference is not installed)",
}


@dataclass(frozen=True)
class Basis:
    """Why a tolerance has its value: the kind of claim (one of BASIS_KINDS) and the reason in words."""

    kind: str
    reason: str

    def __post_init__(self) -> None:
        if self.kind not in BASIS_KINDS:
            raise ValueError(f"unknown tolerance basis {self.kind!r}: expected one of {BASIS_KINDS}")
        if not self.reason.strip():
            raise ValueError("a tolerance basis needs its reason")


#: the band of agreement this project declares for every model-to-model comparison (the spring
#: bed against the FE continuum, our runs against the thesis's figures): +-25 %, declared once,
#: not fitted to any run
MODEL_BAND_REL = 0.25
MODEL_BAND_REASON = (f"declared band of agreement between two models, +-{MODEL_BAND_REL:.0%}, the same for every model-to-model comparison of this "
                     "project (springs vs FE continuum, ours vs the thesis); outside it the case is flagged: the model's limit, not a bug")

#: bases of the metrics every stability-style case checks the same way
STANDARD_BASES: dict[str, Basis] = {
    "outcome_mismatch": Basis(DECLARED_OUTCOME, "the outcome declared in advance (converges, or refused with a message): exact, 0 or 1"),
    "non_finite_outputs": Basis(INVARIANT, "no NaN or inf anywhere in the result directory: exact"),
    "force_residual_rel": Basis(INVARIANT, "force balance to round-off: 1e-8 of the largest load covers float64 over ~1e4 springs with condition numbers up to ~1e4"),
}


def bases_for(tolerance: Mapping[str, float], given: Mapping[str, Basis] | None = None) -> dict[str, Basis]:
    """The basis of each tolerance: ``given`` first, then :data:`STANDARD_BASES`.

    Raises KeyError naming the metrics that have neither (every tolerance must state its reason).
    """
    given = dict(given or {})
    missing = [m for m in tolerance if m not in given and m not in STANDARD_BASES]
    if missing:
        raise KeyError(", ".join(missing))
    return {m: given.get(m, STANDARD_BASES.get(m)) for m in tolerance}


def tolerance_verdicts(metrics: Mapping[str, Any], tolerance: Mapping[str, float], bases: Mapping[str, Basis],
                       not_applicable: bool = False, fe_errors: Mapping[str, float] | None = None,
                       fe_reference: bool = False) -> dict[str, dict[str, Any]]:
    """Per tolerance: value, tolerance, basis kind and reason, and its verdict (module docstring).

    A value is judged by its magnitude (errors are signed). ``not_applicable``: a case refused as
    declared has no values ("n/a"). ``fe_errors``: the FE reference's estimated relative error
    per metric (metric -> error >= 0, e.g. ``{"contact_area_rel_error": 0.07}`` from a Richardson
    estimate of its mesh study; default None: none known); a model band not larger than it gives
    "FE not converged enough to judge" for that metric, whatever the value (its
    ``fe_error`` is recorded). ``fe_reference``: the values compare against an FE reference, so a
    model band without its FE error is "FE error unknown" rather than met.
    """
    out = {}
    fe_errors = dict(fe_errors or {})
    for metric, tol in tolerance.items():
        basis = bases[metric]
        entry = {"value": None, "tolerance": tol, "kind": basis.kind, "reason": basis.reason}
        banded = basis.kind in BANDED_KINDS
        if banded and fe_errors.get(metric) is not None:
            entry["fe_error"] = float(fe_errors[metric])
        if metric in metrics and metrics[metric] is not None:
            value = float(metrics[metric])
            entry["value"] = value
            if "fe_error" in entry and tol <= entry["fe_error"]:
                entry["verdict"] = FE_TOO_COARSE
            elif abs(value) <= tol and banded and fe_reference and "fe_error" not in entry:
                entry["verdict"] = FE_ERROR_UNKNOWN
            elif abs(value) <= tol:
                entry["verdict"] = NOT_JUDGED if basis.kind == SANITY else "met"
            else:
                entry["verdict"] = "outside band" if banded else "fail"
        else:
            entry["verdict"] = "n/a" if not_applicable else "missing"
        out[metric] = entry
    return out


def case_verdict(side_statuses: list[str], verdicts: Mapping[str, Mapping[str, Any]], expected_outcome: str | None,
                 refused_as_declared: bool) -> str:
    """One of CASE_VERDICTS from the sides' statuses ("ok", "refused", "error", "unavailable"),
    the per-tolerance verdicts and the declared outcome (see the module docstring)."""
    if any(s == UNAVAILABLE for s in side_statuses):
        return UNAVAILABLE
    if any(s == ERROR for s in side_statuses):
        return ERROR
    if any(v["verdict"] in ("fail", "missing") for v in verdicts.values()):
        return FAILED
    if expected_outcome == "refused" and refused_as_declared:
        return REFUSED_AS_DECLARED
    if any(v["verdict"] == "outside band" for v in verdicts.values()):
        return FLAGGED
    if any(v["verdict"] in (FE_TOO_COARSE, FE_ERROR_UNKNOWN) for v in verdicts.values()):
        return FE_NOT_CONVERGED
    if any(v["verdict"] == "met" and v["kind"] in CLAIM_KINDS for v in verdicts.values()):
        return VERIFIED
    return RAN


def count_verdicts(verdicts: list[str]) -> dict[str, int]:
    """How many cases ended in each of CASE_VERDICTS (all keys present)."""
    return {v: sum(1 for x in verdicts if x == v) for v in CASE_VERDICTS}


def headline(counts: Mapping[str, int]) -> str:
    """"12 verified, 3 flagged, ..." in CASE_VERDICTS order, leaving out zero counts (but never empty)."""
    words = {ERROR: "crashed", FE_NOT_CONVERGED: "not judged (FE not converged enough)"}
    parts = [f"{counts.get(v, 0)} {words.get(v, v)}" for v in CASE_VERDICTS if counts.get(v, 0)]
    return ", ".join(parts) if parts else "no cases"
