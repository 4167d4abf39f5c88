"""The coupled layer's coarse smoothing space (``[cartilage] thin_layer_smoothing_resolution``): accuracy and cost against the fine one.

The smoothing length sqrt(b) h of the Pade term is about 2.5 mm on a 2 mm layer while springs
are 0.3-1 mm apart, so the vertex operators resolve far more than the smoothed field needs. With
a resolution r > 0 each term is solved on a Galerkin P1 subspace about sqrt(b) h / r across
(``edem.coarse_space``). This script prints

1. the bonded cylinder layer (the thin-layer campaign's base point: 2 mm, 333 N, nu 0.42 and
   0.49, DEM, Pade) at the scene's springs and at a finer spring mesh: displacement, regularised
   peak pressure (edem.pressure_metrics) and contact area, each resolution against the fine
   operator, and the share of the fine vertices the coarse space keeps;
2. the EDEM stance of ``bench_thin_layer`` (Pade, gap and threshold laws, about 3k and 30k
   springs): run time of the fine and coarse layers over the independent springs' (medians, the
   models run alternately round by round), and the final peak pressure and contact area against
   the fine layer's.

    PYTHONPATH=$PWD:$PWD/benchmarks .venv/bin/python benchmarks/bench_coarse_smoothing.py [--resolutions 3,2] [--steps 20] [--rounds 3]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the command line runs (edem.cli.main), before numpy loads

import argparse  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402

from edem.beds import CoupledThinLayer, IndependentSprings, on_bed  # noqa: E402
from edem.pressure_metrics import regularised_peak_pressure_mpa  # noqa: E402
from edem.raycast import RayCaster  # noqa: E402
from edem.scene import load_scene  # noqa: E402
from edem.solver import run  # noqa: E402
from edem.thin_layer import SurfaceMesh  # noqa: E402

_SHARE: list[int] = [0, 0]  # coarse, fine vertices of the coarse spaces built (counted by wrapping SurfaceMesh.coarse_space)
_coarse_space = SurfaceMesh.coarse_space


def _counted(mesh, *args):
    space = _coarse_space(mesh, *args)
    _SHARE[0] += space.transfer.shape[1]
    _SHARE[1] += space.transfer.shape[0]
    return space


SurfaceMesh.coarse_space = _counted


def _share() -> str:
    share = f"{_SHARE[0] / _SHARE[1]:.3f}" if _SHARE[1] else "1 (not coarsened)"
    _SHARE[:] = [0, 0]
    return share


def cylinder_layer(nu: float, resolutions: list[float], spring_mesh_mm: float | None) -> None:
    """The base point on the bonded cylinder layer, fine against each coarse resolution."""
    overrides = {"load.force_n": [0.0, 0.0, 333.0], "cartilage.poissons_ratio": nu, "geometry.plafond_gap_mm": 2.0,
                 "cartilage.thickness_mm": 2.0, "cartilage.coupling": "thin-layer"}
    if spring_mesh_mm is not None:
        overrides["geometry.mesh_size_mm"] = spring_mesh_mm
    scene = load_scene("cylinder-layer", overrides)
    points, triangles = scene.mobile.vertices_mm, scene.mobile.triangles[scene.spring_triangle]
    rows = {}
    for resolution in [0.0, *resolutions]:
        varied = replace(scene, cartilage=on_bed(scene.cartilage, CoupledThinLayer.coupling, thin_layer_smoothing_resolution=resolution))
        _share()
        started = time.perf_counter()
        step = run(varied, "dem").steps[-1]
        elapsed = time.perf_counter() - started
        peak = regularised_peak_pressure_mpa(points, triangles, step.pressure_mpa, at_points=False)
        rows[resolution] = (float(np.linalg.norm(step.displacement_mm)), peak, step.contact_area_mm2, elapsed, _share())
    d0, p0, a0, _, _ = rows[0.0]
    print(f"cylinder layer 2 mm, 333 N, nu {nu:g}, {triangles.shape[0]} springs, Pade, DEM:")
    for resolution, (d, p, a, t, share) in rows.items():
        name = "fine" if resolution == 0.0 else f"resolution {resolution:g}"
        print(f"  {name:14s}: displacement {d:.5f} mm ({100 * (d / d0 - 1):+.2f} %), regularised peak {p:.4f} MPa ({100 * (p / p0 - 1):+.2f} %), "
              f"area {a:.2f} mm^2 ({100 * (a / a0 - 1):+.2f} %); DEM {t:.2f} s; coarse vertices / fine {share}", flush=True)


def stance(size_mm: float, law: str, steps: int, rounds: int, resolutions: list[float]) -> None:
    """The stance of bench_thin_layer: independent springs, the fine and the coarse Pade layers."""
    from bench_edem import stance_like_scene

    base = stance_like_scene(size_mm, steps)
    caster = RayCaster(base.fixed.vertices_mm, base.fixed.triangles)
    cartilage = replace(base.cartilage, poissons_ratio=0.45, law=law, thickness_mm=2.0 if law != "threshold" else None)
    models = {"springs": replace(base, cartilage=on_bed(cartilage, IndependentSprings.coupling))}
    for resolution in [0.0, *resolutions]:
        name = "fine" if resolution == 0.0 else f"resolution {resolution:g}"
        models[name] = replace(base, cartilage=on_bed(cartilage, CoupledThinLayer.coupling, thin_layer_smoothing_resolution=resolution))
    times: dict[str, list[float]] = {name: [] for name in models}
    last, shares = {}, {}
    run(models["springs"], "edem", caster=caster)  # warm-up: imports, first Embree traversal
    for _ in range(rounds):
        for name, scene in models.items():
            _share()
            result = run(scene, "edem", caster=caster)
            shares[name] = _share()
            times[name].append(result.wall_time_s)
            last[name] = result
    springs_s = statistics.median(times["springs"])
    fine = last["fine"].steps[-1]
    for name, result in last.items():
        step, t = result.steps[-1], statistics.median(times[name])
        against = "" if name in ("springs", "fine") else (f"; against fine: peak {100 * (step.peak_pressure_mpa / fine.peak_pressure_mpa - 1):+.2f} %, "
                                                          f"area {100 * (step.contact_area_mm2 / fine.contact_area_mm2 - 1):+.2f} %")
        coarse = "" if name == "springs" else f", coarse vertices / fine {shares[name]}"
        print(f"  {law:9s} {result.n_springs:6d} springs, {name:14s}: run {t:7.3f} s (median of {rounds}) = {t / springs_s:5.2f}x the springs{coarse}; "
              f"final peak {step.peak_pressure_mpa:.3f} MPa, area {step.contact_area_mm2:.1f} mm^2{against}", flush=True)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolutions", default="3,2", help="coarse cells per smoothing length")
    parser.add_argument("--nus", default="0.42,0.49", help="the cylinder layer's Poisson's ratios ('' to skip)")
    parser.add_argument("--layer-meshes", default="scene,0.3", help="the cylinder layer's spring mesh sizes, mm ('scene': its own)")
    parser.add_argument("--steps", type=int, default=20, help="time points of the stance")
    parser.add_argument("--rounds", type=int, default=3, help="runs per model (median)")
    parser.add_argument("--sizes", default="0.94,0.3", help="the stance's spring mesh sizes, mm ('' to skip)")
    parser.add_argument("--laws", default="gap,threshold")
    args = parser.parse_args()
    resolutions = [float(r) for r in args.resolutions.split(",")]
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    for layer_mesh in args.layer_meshes.split(","):
        for nu in [float(v) for v in args.nus.split(",") if v]:
            cylinder_layer(nu, resolutions, None if layer_mesh == "scene" else float(layer_mesh))
    for size in [float(s) for s in args.sizes.split(",") if s]:
        for law in args.laws.split(","):
            stance(size, law, args.steps, args.rounds, resolutions)
    print(f"load average {os.getloadavg()[0]:.1f}")
