"""``population-coupled``: the 1000 subjects of ``population`` on the coupled thin layer (Pade symbol).

The same seeded subject-like ankles, stance and 1.5 mm spring mesh as :mod:`.population`, with
``cartilage.coupling = "thin-layer"`` (the scene's default): the gap law's layer bonded to the talus
over its whole surface. The spread of the population under the accurate bed, beside the
independent springs' (a second campaign, so the two stay cached side by side).
"""

from __future__ import annotations

from verification.campaign_model import Campaign
from verification.campaigns.population import POPULATION_SIZE
from verification.campaigns.population import campaign as population_campaign

#: projected from CPU times (benchmarks/bench_campaign_throughput.py, 2026-11-26 at load 9-12):
#: 497 ms per case, start-up 2.3 s, report 4.2 s, on 2 cores 255 s (an upper figure: the CPU times
#: at load run about 1.3x a quiet machine's, docs/campaigns.md#the-campaigns). Measured over the
#: 1000 with --jobs 2: 1372 s at load 7-12, 1428 s at load 6-16 (508 s and 520 s of CPU time)
EXPECTED_TIME_S = 255.0


def campaign(n: int = POPULATION_SIZE) -> Campaign:
    return population_campaign(n, coupling="thin-layer")
