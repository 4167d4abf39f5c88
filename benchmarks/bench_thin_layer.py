"""Coupled thin-layer DEM vs independent-spring DEM (issue 10 goal: ratio <= 3 at 3k springs, <= 5 at 30k).

The idealised ankle of ``bench_edem`` (tibia turned, load ramped to 4190 N), nu 0.45, with the
threshold law (the layer is the candidates) and the gap law (a 2 mm layer on the whole talus), solved by DEM with ``coupling = "none"`` and ``"thin-layer"``, at 5 instants (a short
run, where the layer's once-per-run set-up weighs most) and at the stance's 65. The Embree scene
is built once. Runs the models alternately (independent springs; the coupled layer with the Pade
symbol, and at 5 instants with the two-pole symbol too) and prints, per size, the medians of 7
runs of the whole DEM run and of its solve stage (assembly + unilateral solve, without the ray
casting they share), and the ratios.

    .venv/bin/python benchmarks/bench_thin_layer.py
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the command line runs (edem.cli.main), before numpy loads

import statistics  # noqa: E402
from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402
from bench_edem import stance_like_scene  # noqa: E402

from edem.raycast import RayCaster  # noqa: E402
from edem.solver import run  # noqa: E402


def bench(mesh_size_mm: float, target_ratio: float, rounds: int = 7, n_steps: int = 5, law: str = "threshold", symbols: tuple[str, ...] = ("pade",)) -> None:
    base = stance_like_scene(mesh_size_mm, n_steps)
    caster = RayCaster(base.fixed.vertices_mm, base.fixed.triangles)
    couplings = ("none", *symbols)
    # The gap law: a 2 mm layer bonded to all of the talus (its coupled layer is the whole surface).
    cartilage = replace(base.cartilage, poissons_ratio=0.45, law=law, thickness_mm=2.0 if law != "threshold" else None)
    scenes = {c: replace(base, cartilage=replace(cartilage, coupling="none") if c == "none" else replace(cartilage, coupling="thin-layer", thin_layer_symbol=c))
              for c in couplings}
    totals: dict[str, list[float]] = {c: [] for c in couplings}
    solves: dict[str, list[float]] = {c: [] for c in couplings}
    results = {}
    for coupling in couplings:
        run(scenes[coupling], "dem", caster=caster)  # warm-up
    # Alternate the two models round by round, so a load spike of the shared machine hits both.
    for _ in range(rounds):
        for coupling in couplings:
            results[coupling] = run(scenes[coupling], "dem", caster=caster)
            totals[coupling].append(results[coupling].wall_time_s)
            solves[coupling].append(results[coupling].seconds["solve"])
    medians = {}
    for coupling in couplings:
        result, last = results[coupling], results[coupling].steps[-1]
        medians[coupling] = (statistics.median(totals[coupling]), statistics.median(solves[coupling]))
        print(
            f"{law:9s} {result.n_springs:6d} springs, {coupling:10s}: run {1e3 * medians[coupling][0]:8.1f} ms, solve {1e3 * medians[coupling][1]:8.1f} ms "
            f"(median of {rounds}, {n_steps} DEM instants); mean iterations {np.mean([s.iterations for s in result.steps]):.1f}, "
            f"final peak {last.peak_pressure_mpa:.2f} MPa, area {last.contact_area_mm2:.0f} mm^2"
        )
    for symbol in symbols:
        run_ratio = medians[symbol][0] / medians["none"][0]
        solve_ratio = medians[symbol][1] / medians["none"][1]
        print(f"  ratio coupled ({symbol}) / independent: run {run_ratio:.2f}x, solve stage {solve_ratio:.2f}x (goal <= {target_ratio}x on the run: "
              f"{'met' if run_ratio <= target_ratio else 'MISSED'})")


if __name__ == "__main__":
    for law in ("threshold", "gap"):
        for n_steps in (5, 65):
            # The two-pole symbol (an indefinite block factored by SuperLU) at the short run only:
            # at 30k springs and 65 instants one gap-law run takes about a minute.
            symbols = ("pade", "two-pole") if n_steps < 10 else ("pade",)
            bench(0.94, 3.0, n_steps=n_steps, law=law, symbols=symbols)
            bench(0.3, 5.0, n_steps=n_steps, rounds=7 if n_steps < 10 else 3, law=law, symbols=symbols)
