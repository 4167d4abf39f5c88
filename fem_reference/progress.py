"""Progress lines from inside one FE contact solve (``edem fe --progress``; automatic on a terminal).

The step bar of ``edem fe`` counts time points, but one time point of a large model can run for
minutes (a P2 knee slab took 557 s) with nothing on the screen. :func:`fem_reference.solve_contact`
given a :class:`SolveProgress` writes

* one line per Newton iteration: the iteration, the residual norm (N), the contact nodes (P1
  nodes of the contact surface that carry pressure), how many entered and left the contact
  since the previous iteration, and the seconds since the solve began;
* on the Krylov path (when the LU would not fit, :func:`fem_reference.sizing.direct_fits`), the inner iteration
  and its residual at most once every ``krylov_every_s`` seconds (a KSP monitor).

Nothing is written before the solve has run ``quiet_s`` seconds, so a terminal is not flooded by
the many short solves of a small model. In parallel every rank calls the monitors (counting the
contact nodes is a collective assembly) and rank 0 alone writes.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

#: seconds a solve runs before ``edem fe`` on a terminal starts writing (forced --progress: 0)
TERMINAL_QUIET_S = 5.0
#: at most one Krylov line per this many seconds
KRYLOV_EVERY_S = 2.0


@dataclass
class SolveProgress:
    """Writes the progress lines of one solve through ``write`` (one line per call, no newline).

    ``label`` names the solve (e.g. the time point); :meth:`for_solve` gives a reporter for the
    next solve with its own start time.
    """

    write: Callable[[str], None]
    label: str = ""
    quiet_s: float = 0.0
    krylov_every_s: float = KRYLOV_EVERY_S
    clock: Callable[[], float] = time.perf_counter
    newton_iteration: int = field(default=0, init=False)
    _start: float = field(default=0.0, init=False, repr=False)
    _last_krylov: float = field(default=-math.inf, init=False, repr=False)

    def __post_init__(self) -> None:
        self._start = self.clock()

    def for_solve(self, label: str) -> SolveProgress:
        """A reporter for a new solve (same writer and rates), its clock starting now."""
        return dataclasses.replace(self, label=label)

    def elapsed_s(self) -> float:
        return self.clock() - self._start

    def _prefix(self) -> str:
        return f"fe: {self.label}: " if self.label else "fe: "

    def newton(self, iteration: int, residual_n: float, contact_nodes: int, entered: int, left: int,
               krylov: int | None = None) -> None:
        """After Newton iteration ``iteration`` (0 = the initial guess) with residual norm ``residual_n``;
        ``krylov``: the inner Krylov iterations of the step that led here (iterative path)."""
        self.newton_iteration = iteration
        elapsed = self.elapsed_s()
        if elapsed < self.quiet_s:
            return
        change = "" if iteration == 0 else f" (+{entered} -{left})"
        inner = "" if krylov is None or iteration == 0 else f", {krylov} Krylov iterations"
        self.write(f"{self._prefix()}Newton {iteration}: |F| = {residual_n:.3e} N, {contact_nodes} contact nodes{change}{inner}, "
                   f"{elapsed:.1f} s")

    def krylov(self, iteration: int, residual: float, method: str) -> None:
        """Inner Krylov iteration ``iteration`` of the current Newton step (throttled)."""
        now = self.clock()
        if now - self._start < self.quiet_s or now - self._last_krylov < self.krylov_every_s:
            return
        self._last_krylov = now
        self.write(f"{self._prefix()}  Newton {self.newton_iteration + 1}, inner {method}: iteration {iteration}, "
                   f"|r| = {residual:.3e}, {now - self._start:.1f} s")
