"""Statuses of campaign sides, cases and analyses: one enum, whose values metrics.json holds.

A side ends ``ok``, ``refused`` (InputError / SolverError: a declared outcome can expect it),
``unavailable`` (cannot run on this installation, e.g. no dolfinx; never faked) or ``error``
(a crash). A case is ``passed`` or ``failed`` against its tolerance (or ``unavailable`` /
``error`` after its sides); an analysis is ``passed`` / ``failed`` when judged, ``reported`` when
it only shows numbers, ``unavailable`` without values.
"""

from __future__ import annotations

from enum import StrEnum


class Status(StrEnum):
    OK = "ok"
    REFUSED = "refused"
    UNAVAILABLE = "unavailable"
    ERROR = "error"
    PASSED = "passed"
    FAILED = "failed"
    REPORTED = "reported"


OK, REFUSED, UNAVAILABLE, ERROR = Status.OK, Status.REFUSED, Status.UNAVAILABLE, Status.ERROR
PASSED, FAILED, REPORTED = Status.PASSED, Status.FAILED, Status.REPORTED
