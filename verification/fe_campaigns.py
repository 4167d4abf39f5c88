"""Names of the EDEM/DEM-vs-FE campaigns (issue 5) under their former module.

The campaigns are :mod:`verification.campaigns.cylinder_plane`, ``subject`` and
``error_vs_runtime``; their truth sides live in :mod:`verification.sides` and the Pareto
analysis in :mod:`verification.analyses`.
"""

from verification.analyses import pareto_front
from verification.campaigns.cylinder_plane import SWEEP_LOADS_N, SWEEP_NUS, SWEEP_THICKNESS_MM
from verification.sides import TRUTH_STEPS, resample_load

__all__ = ["SWEEP_LOADS_N", "SWEEP_NUS", "SWEEP_THICKNESS_MM", "TRUTH_STEPS", "pareto_front", "resample_load"]
