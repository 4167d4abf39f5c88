"""Throughput of edem.raycast (docs/method.md#1-two-rigid-bones-and-a-bed-of-springs, docs/method.md#8-built-in-geometries): rays/s of the signed-window spring-length cast.

Scene (docs/method.md#8-built-in-geometries, idealised ankle): mobile body M = cylinder patch, R = 20 mm, width 28 mm, arc
114 degrees (axis along y, dome top at z = 20 mm); fixed body F = plane 1.5 mm above the dome top,
facing down. One ray per triangle of M, from its centroid along its outward normal; window
h_max = 3.5 mm (about 42 % of the rays hit, as in the thesis's standing case).

Prints the median of 7 timed rounds (after one warm-up) for 3k and 30k rays against ~3k and ~60k
triangles, for the Embree backend, raw embreex traversal for comparison, and the numpy reference
on the smallest case. Run: ``.venv/bin/python benchmarks/bench_raycast.py`` (well under 30 s).
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from edem.raycast import RayCaster  # noqa: E402

RADIUS_MM = 20.0
WIDTH_MM = 28.0
ARC_DEG = 114.0
GAP_MM = 1.5
H_MAX_MM = 3.5
ROUNDS = 7


def grid_triangles(nu: int, nv: int) -> np.ndarray:
    """Two triangles per cell of an (nu+1) x (nv+1) vertex grid, right-hand rule along +u x +v."""
    idx = np.arange((nu + 1) * (nv + 1)).reshape(nu + 1, nv + 1)
    a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
    c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    return np.r_[np.c_[a, b, c], np.c_[a, c, d]]


def cylinder_patch(n_triangles: int) -> tuple[np.ndarray, np.ndarray]:
    """Centroids and outward unit normals of a triangulated cylinder patch with ~n_triangles."""
    arc_mm = RADIUS_MM * np.deg2rad(ARC_DEG)
    cell = np.sqrt(arc_mm * WIDTH_MM / (n_triangles / 2))
    nu, nv = max(1, round(arc_mm / cell)), max(1, round(WIDTH_MM / cell))
    theta = np.linspace(-0.5, 0.5, nu + 1) * np.deg2rad(ARC_DEG)
    y = np.linspace(-0.5, 0.5, nv + 1) * WIDTH_MM
    gt, gy = np.meshgrid(theta, y, indexing="ij")
    vertices = np.c_[RADIUS_MM * np.sin(gt.ravel()), gy.ravel(), RADIUS_MM * np.cos(gt.ravel())]
    # e_theta x e_y = (sin theta, 0, cos theta): the right-hand rule already points outward.
    triangles = grid_triangles(nu, nv)
    a, b, c = (vertices[triangles[:, i]] for i in range(3))
    normals = np.cross(b - a, c - a)
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    return (a + b + c) / 3.0, normals


def plafond(n_triangles: int) -> tuple[np.ndarray, np.ndarray]:
    """Plane GAP_MM above the dome top, 40 x 32 mm, facing down (towards M), ~n_triangles."""
    size_x, size_y = 40.0, 32.0
    cell = np.sqrt(size_x * size_y / (n_triangles / 2))
    nu, nv = max(1, round(size_x / cell)), max(1, round(size_y / cell))
    gx, gy = np.meshgrid(np.linspace(-0.5, 0.5, nu + 1) * size_x,
                         np.linspace(-0.5, 0.5, nv + 1) * size_y, indexing="ij")
    vertices = np.c_[gx.ravel(), gy.ravel(), np.full(gx.size, RADIUS_MM + GAP_MM)]
    return vertices, grid_triangles(nu, nv)[:, [0, 2, 1]]  # +x x +y = +z: flip to face down


def median_seconds(fn) -> float:
    fn()  # warm-up
    times = []
    for _ in range(ROUNDS):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    print(f"ray cast benchmark: median of {ROUNDS} rounds, window h_max = {H_MAX_MM} mm")
    print(f"{'rays':>7} {'F tris':>7} {'build ms':>9} {'hit %':>6} "
          f"{'edem embree rays/s':>19} {'raw embreex rays/s':>19} {'numpy rays/s':>13}")
    for n_rays in (3_000, 30_000):
        origins, directions = cylinder_patch(n_rays)
        for n_tri in (3_000, 60_000):
            vertices, triangles = plafond(n_tri)
            start = time.perf_counter()
            caster = RayCaster(vertices, triangles, backend="embree")
            build_ms = 1e3 * (time.perf_counter() - start)
            hits = caster.cast(origins, directions, H_MAX_MM)
            hit_pct = 100.0 * np.mean(hits.triangle >= 0)
            ours = median_seconds(lambda: caster.cast(origins, directions, H_MAX_MM))

            # Bare embreex traversal of the same window rays (no float64 work, one pass).
            o32 = np.ascontiguousarray(origins - H_MAX_MM * directions - caster._centre_mm,
                                       dtype=np.float32)
            d32 = np.ascontiguousarray(directions, dtype=np.float32)
            raw = median_seconds(lambda: caster._scene.run(
                o32, d32, dists=np.full(len(o32), 2 * H_MAX_MM, np.float32), output=1))

            numpy_rate = "-"
            if n_rays * n_tri <= 10_000_000:
                reference = RayCaster(vertices, triangles, backend="numpy")
                check = reference.cast(origins, directions, H_MAX_MM)
                assert np.array_equal(check.triangle >= 0, hits.triangle >= 0)
                assert np.allclose(check.spring_length_mm, hits.spring_length_mm, rtol=1e-9)
                t_np = median_seconds(lambda: reference.cast(origins, directions, H_MAX_MM))
                numpy_rate = f"{len(origins) / t_np:,.0f}"
            print(f"{len(origins):>7} {len(triangles):>7} {build_ms:>9.1f} {hit_pct:>6.1f} "
                  f"{len(origins) / ours:>19,.0f} {len(origins) / raw:>19,.0f} {numpy_rate:>13}")


if __name__ == "__main__":
    main()
