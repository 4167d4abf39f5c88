"""Statuses of campaign sides, cases and analyses: one enum, whose values metrics.json holds.

A side ends ``ok``, ``refused`` (InputError / SolverError: a declared outcome can expect it),
``unavailable`` (cannot run on this installation, e.g. no dolfinx; never faked) or ``error``
(a crash). A case ends in one verdict (what each means, and how a tolerance's basis decides it:
:mod:`verification.verdicts`, docs/campaigns.md#verdicts): ``verified``, ``flagged`` (outside a
declared model band), ``FE not converged enough to judge`` (a band no wider than the FE
reference's own estimated error), ``refused as declared``, ``ran`` (no accuracy verdict), ``failed``, or
``unavailable`` / ``error`` after its sides. An analysis is ``verified`` / ``failed`` when
judged, ``reported`` when it only shows numbers, ``flagged`` when some of its rows fall outside
their declared band, ``unavailable`` without values.
"""

from __future__ import annotations

from enum import StrEnum


class Status(StrEnum):
    OK = "ok"
    REFUSED = "refused"
    UNAVAILABLE = "unavailable"
    ERROR = "error"
    VERIFIED = "verified"
    FLAGGED = "flagged"
    REFUSED_AS_DECLARED = "refused as declared"
    RAN = "ran"
    FAILED = "failed"
    REPORTED = "reported"
    FE_NOT_CONVERGED = "FE not converged enough to judge"


OK, REFUSED, UNAVAILABLE, ERROR = Status.OK, Status.REFUSED, Status.UNAVAILABLE, Status.ERROR
VERIFIED, FLAGGED, REFUSED_AS_DECLARED, RAN = Status.VERIFIED, Status.FLAGGED, Status.REFUSED_AS_DECLARED, Status.RAN
FAILED, REPORTED, FE_NOT_CONVERGED = Status.FAILED, Status.REPORTED, Status.FE_NOT_CONVERGED
