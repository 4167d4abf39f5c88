"""Prototype (issue 23, item 2): the coupled layer's smoothing on a coarser P1 space than the springs.

The smoothing length sqrt(b) h of the Pade term is about 2.5 mm on a 2 mm layer while the
springs are 0.3-1 mm apart, so the vertex operators H = M + K (``edem.thin_layer``) resolve far
more than the field needs. Here the smoothing is solved on a coarse subspace of the fine P1
space: v_fine = P v_coarse, with P (V, V_c) the barycentric interpolation of the fine vertices in
a coarse triangulation, and the Galerkin operators

    H_c = P^T H P,   Z_c = P^T Z,   C_c = diag(c_loc / A) + sigma Z_c^T H_c^-1 Z_c.

Properties kept from the fine operator (module docstring of ``edem.thin_layer``):
* C_c is symmetric; for sigma = -1 it stays positive definite, since P H_c^-1 P^T <= H^-1 (a
  Galerkin projection in H's energy), so Z_c^T H_c^-1 Z_c <= Z^T H^-1 Z <= Z^T M^-1 Z;
* S 1 = 1 on a layer without free edges: barycentric weights sum to one (P 1 = 1), so
  H_c 1 = P^T M 1 = P^T Q^T diag(A c_nl) 1 and a uniform pressure gives the uniform field;
* Dirichlet at free edges: the fine vertices there are not in the fine space, so P's rows there
  are dropped (the coarse functions vanish on them);
* P -> I as the coarse size -> the spring size gives the fine operator back.

Coarse vertices: one fine vertex per cube of side ``coarse_mm`` (the one nearest its cube's
members' mean), triangulated by scipy's Delaunay in the plane normal to the surface's mean
normal (so this prototype takes surfaces that are height fields over that plane: the ideal
ankle's talus dome, the cylinder layer's plane; it refuses others). A fine vertex outside the
coarse hull takes its nearest coarse vertex (weight 1, so P 1 = 1 still holds).

It prints (1) the EDEM stance of ``bench_thin_layer`` (gap and threshold laws, Pade, 3k and 30k
springs): run time coupled / independent springs with the fine and the coarse smoothing, in one
run, and the final peak pressure and contact area of each; (2) the bonded cylinder layer (2 mm,
333 N, nu 0.42 and 0.49, DEM, the thin-layer campaign's base point): displacement, regularised
peak pressure (edem.pressure_metrics) and contact area, fine against coarse.

    PYTHONPATH=$PWD:$PWD/benchmarks .venv/bin/python benchmarks/bench_coarse_smoothing.py [--steps 20] [--rounds 2] [--coarse 0.8,1.2]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import statistics  # noqa: E402
from dataclasses import dataclass, replace  # noqa: E402

import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from scipy.spatial import Delaunay, cKDTree  # noqa: E402

import edem.beds as beds  # noqa: E402
import edem.thin_layer_contact as contact  # noqa: E402
from edem.thin_layer import LAYER_SYMBOLS, LayerCompliance, OperatorPattern, SmoothingTerm, SurfaceMesh, layer_compliance  # noqa: E402

# --------------------------------------------------------------------------- the coarse space


def _seeds(x: np.ndarray, coarse_mm: float) -> np.ndarray:
    """Indices into x (k, 3): one point per cube of side ``coarse_mm``, the one nearest its cube's members' mean."""
    if x.shape[0] == 0:
        return np.zeros(0, np.int64)
    cube = np.floor((x - x.min(axis=0)) / coarse_mm).astype(np.int64)
    _, group = np.unique(cube, axis=0, return_inverse=True)
    group = group.ravel()
    n_groups = group.max() + 1
    centre = np.column_stack([np.bincount(group, weights=x[:, k], minlength=n_groups) for k in range(3)]) / np.bincount(group)[:, None]
    distance = np.linalg.norm(x - centre[group], axis=1)
    order = np.lexsort((distance, group))  # per group, nearest first
    return order[np.r_[True, group[order][1:] != group[order][:-1]]]


def coarse_transfer(vertices_mm: np.ndarray, triangles: np.ndarray, kept: np.ndarray, edge: np.ndarray, coarse_mm: float) -> sp.csr_matrix:
    """P (kept.size, V_c): barycentric weights of the fine space's vertices ``kept`` in a coarse
    triangulation of the ``triangles`` (m, 3); ``edge``: their vertices where the field vanishes
    (module docstring). The coarse vertices are fine ones (kept seeds: P has their identity rows,
    so it has full column rank), plus seeds on the edge, which carry no unknown."""
    tri = np.asarray(triangles, np.int64)
    normal = np.cross(vertices_mm[tri[:, 1]] - vertices_mm[tri[:, 0]], vertices_mm[tri[:, 2]] - vertices_mm[tri[:, 0]])
    mean = normal.sum(axis=0)
    mean /= np.linalg.norm(mean)
    if np.min(normal @ mean) <= 0.0:
        raise ValueError("the prototype takes height fields over the plane normal to the mean normal only")
    e1 = np.cross(mean, [1.0, 0.0, 0.0] if abs(mean[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(mean, e1)
    inner = kept[_seeds(vertices_mm[kept], coarse_mm)]
    outer = edge[_seeds(vertices_mm[edge], coarse_mm)]
    seeds = np.concatenate([inner, outer])
    coarse_plane = np.column_stack([vertices_mm[seeds] @ e1, vertices_mm[seeds] @ e2])
    plane = np.column_stack([vertices_mm[kept] @ e1, vertices_mm[kept] @ e2])
    triangulation = Delaunay(coarse_plane)
    simplex = triangulation.find_simplex(plane)
    rows, cols, vals = [], [], []
    inside = np.flatnonzero(simplex >= 0)
    transform = triangulation.transform[simplex[inside]]  # (k, 3, 2)
    bary = np.einsum("kij,kj->ki", transform[:, :2], plane[inside] - transform[:, 2])
    bary = np.column_stack([bary, 1.0 - bary.sum(axis=1)])
    rows.append(np.repeat(inside, 3))
    cols.append(triangulation.simplices[simplex[inside]].ravel())
    vals.append(bary.ravel())
    outside = np.flatnonzero(simplex < 0)
    if outside.size:
        _, nearest = cKDTree(coarse_plane[: inner.size]).query(plane[outside])
        rows.append(outside)
        cols.append(nearest)
        vals.append(np.ones(outside.size))
    r, c, v = np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)
    keep = (np.abs(v) > 1e-12) & (c < inner.size)  # the edge seeds' weights are dropped: the field vanishes there
    p = sp.csr_matrix((v[keep], (r[keep], c[keep])), shape=(kept.size, inner.size))
    p.sum_duplicates()
    return p


@dataclass(frozen=True)
class CoarseTerm(SmoothingTerm):
    """A smoothing term on the coarse space: H is H_c (on the coupled pattern), Z is Z_c; the
    coupled matrix's data adds sigma x_t z_t z_t^T over each spring's coarse pairs."""

    pair_slot: np.ndarray = None  # (k,) slot of each spring's coarse pair
    pair_coefficient: np.ndarray = None  # (k,) z_ta z_tb
    pair_spring: np.ndarray = None  # (k,)

    def coupled_data(self, spring_weight: np.ndarray) -> np.ndarray:
        w = spring_weight[self.pair_spring]
        nz = w != 0.0
        return self.h.data + np.bincount(self.pair_slot[nz], weights=self.sigma * self.pair_coefficient[nz] * w[nz], minlength=self.h.data.shape[0])


#: id(mesh) -> (mesh, its vertices (n, 3) mm, the coarse size mm); the prototype's way to give the layer its coarse space
TRANSFERS: dict[int, tuple[SurfaceMesh, np.ndarray, float]] = {}
#: structure per (id(mesh), cells, edge, dirichlet): (P, pattern, slots...), and the last H_c by H's data
_STRUCTURE: dict = {}
_COUNTS = {"coarse_vertices": 0, "fine_vertices": 0}


def _kept_vertices(mesh: SurfaceMesh, cells: np.ndarray, edge_at_cells: bool, dirichlet: bool) -> tuple[np.ndarray, np.ndarray]:
    """The fine space's vertices, in its order (as ``SurfaceMesh.operator_pattern`` numbers them),
    and the cells' vertices where the field vanishes."""
    if not dirichlet:
        free = np.zeros(mesh.free_edge_vertex.shape[0], bool)
    elif edge_at_cells:
        free = mesh.free_edge_vertex | mesh.boundary_of(cells)
    else:
        free = mesh.free_edge_vertex
    kept = np.zeros(free.shape[0], bool)
    kept[mesh.triangles[cells]] = True
    return np.flatnonzero(kept & ~free), np.flatnonzero(kept & free)


def _structure(mesh, transfer, cells, pattern: OperatorPattern, edge_at_cells, dirichlet):
    key = (id(mesh), np.asarray(cells).tobytes(), edge_at_cells, dirichlet)
    cached = _STRUCTURE.get(key)
    if cached is not None:
        return cached
    if len(_STRUCTURE) > 8:
        _STRUCTURE.clear()
    _, vertices_mm, coarse_mm = transfer
    kept, edge = _kept_vertices(mesh, cells, edge_at_cells, dirichlet)
    p = coarse_transfer(vertices_mm, mesh.triangles[cells], kept, edge, coarse_mm)
    qp = (pattern.q @ p).tocsr()  # (m, V_c): spring value from coarse vertex values
    ones = pattern.matrix(np.ones(pattern.indices.shape[0]))
    structure = (abs(p).T @ ones @ abs(p)).tocsc()
    structure.sort_indices()
    n_c = p.shape[1]
    col = np.repeat(np.arange(n_c), np.diff(structure.indptr))
    keys = col * n_c + structure.indices  # sorted (canonical CSC)
    # Every spring's coarse pairs (a, b) of its support in Q P.
    counts = np.diff(qp.indptr)
    m = qp.shape[0]
    k_max = int(counts.max(initial=0))
    support = np.full((m, k_max), -1)
    value = np.zeros((m, k_max))
    position = np.arange(qp.indices.shape[0]) - np.repeat(qp.indptr[:-1], counts)
    support[np.repeat(np.arange(m), counts), position] = qp.indices
    value[np.repeat(np.arange(m), counts), position] = qp.data
    a, b = support[:, :, None], support[:, None, :]
    valid = (a >= 0) & (b >= 0)
    spring = np.broadcast_to(np.arange(m)[:, None, None], valid.shape)[valid]
    pair_key = (np.broadcast_to(b, valid.shape)[valid] * n_c + np.broadcast_to(a, valid.shape)[valid])
    slot = np.searchsorted(keys, pair_key)
    coefficient = (value[:, :, None] * value[:, None, :])[valid]
    coarse_pattern = OperatorPattern(structure.indices, structure.indptr, np.zeros((0, 9), np.int64), qp)
    cached = {"p": p, "qp": qp, "keys": keys, "pattern": coarse_pattern, "slot": slot, "coefficient": coefficient, "spring": spring, "h": None}
    _STRUCTURE[key] = cached
    return cached


def coarse_layer_compliance(mesh, cells, thickness_mm, youngs_modulus_mpa, poissons_ratio, edge_at_cells=False, symbol="pade") -> LayerCompliance:
    """``edem.thin_layer.layer_compliance`` with each smoothing term on the coarse space of ``TRANSFERS[id(mesh)]``."""
    transfer = TRANSFERS[id(mesh)]
    g = youngs_modulus_mpa / (2.0 * (1.0 + poissons_ratio))
    h = np.broadcast_to(np.asarray(thickness_mm, float), cells.shape)
    h_over_g = h / g
    model = LAYER_SYMBOLS[symbol](poissons_ratio)
    terms = []
    for strength, b, dirichlet in zip(model.strengths, model.screenings, model.dirichlet):
        c_nl = np.broadcast_to(abs(strength) * h_over_g, cells.shape)
        fine_h, pattern = mesh.smoothing_operators(cells, c_nl, b * h * h * c_nl, edge_at_cells, dirichlet)
        s = _structure(mesh, transfer, cells, pattern, edge_at_cells, dirichlet)
        if s["h"] is None or not np.array_equal(s["h"][0], fine_h.data):
            galerkin = (s["p"].T @ fine_h @ s["p"]).tocoo()
            n_c = s["p"].shape[1]
            data = np.zeros(s["keys"].shape[0])
            np.add.at(data, np.searchsorted(s["keys"], galerkin.col * n_c + galerkin.row), galerkin.data)
            s["h"] = (fine_h.data.copy(), s["pattern"].matrix(data))
        _COUNTS["coarse_vertices"] += s["p"].shape[1]
        _COUNTS["fine_vertices"] += s["p"].shape[0]
        z_t = sp.csr_matrix((s["qp"].data * np.repeat(c_nl, np.diff(s["qp"].indptr)), s["qp"].indices, s["qp"].indptr), shape=s["qp"].shape)
        c2 = c_nl[s["spring"]] ** 2
        terms.append(CoarseTerm(float(np.sign(strength)), z_t.T.tocsr(), s["h"][1], c_nl, s["pattern"], s["slot"], s["coefficient"] * c2, s["spring"]))
    return LayerCompliance(model.local * h_over_g / mesh.area_mm2[cells], tuple(terms), mesh.memo.setdefault("factor", {}))


def use_coarse(coarse_mm: float | None) -> None:
    """Route the coupled bed through the coarse smoothing (``coarse_mm``) or back to the fine one (None)."""
    if coarse_mm is None:
        contact.layer_compliance = layer_compliance
        beds.coupled_layer_mesh = contact.coupled_layer_mesh
        return

    def mesh_with_transfer(scene) -> SurfaceMesh:
        mesh = contact.coupled_layer_mesh(scene)
        TRANSFERS[id(mesh)] = (mesh, scene.mobile.vertices_mm, coarse_mm)
        return mesh

    contact.layer_compliance = coarse_layer_compliance
    beds.coupled_layer_mesh = mesh_with_transfer


# --------------------------------------------------------------------------- measurements


def stance(size_mm: float, law: str, steps: int, rounds: int, coarse_sizes: list[float]) -> None:
    """The stance of bench_thin_layer: independent springs, fine Pade and coarse Pade, alternately."""
    from bench_edem import stance_like_scene

    from edem.raycast import RayCaster
    from edem.solver import run

    base = stance_like_scene(size_mm, steps)
    caster = RayCaster(base.fixed.vertices_mm, base.fixed.triangles)
    cartilage = replace(base.cartilage, poissons_ratio=0.45, law=law, thickness_mm=2.0 if law != "threshold" else None)
    springs = replace(base, cartilage=replace(cartilage, coupling="none"))
    coupled = replace(base, cartilage=replace(cartilage, coupling="thin-layer", thin_layer_symbol="pade"))
    models = [("springs", springs, None), ("fine", coupled, None)] + [(f"coarse {c:g} mm", coupled, c) for c in coarse_sizes]
    times: dict[str, list[float]] = {name: [] for name, _, _ in models}
    last = {}
    run(springs, "edem", caster=caster)
    for _ in range(rounds):
        for name, scene, coarse in models:
            use_coarse(coarse)
            _COUNTS.update(coarse_vertices=0, fine_vertices=0)
            result = run(scene, "edem", caster=caster)
            times[name].append(result.wall_time_s)
            last[name] = (result, dict(_COUNTS))
    use_coarse(None)
    base_time = statistics.median(times["springs"])
    fine = last["fine"][0].steps[-1]
    for name, _, _ in models:
        result, counts = last[name]
        step = result.steps[-1]
        t = statistics.median(times[name])
        size = f", coarse space {counts['coarse_vertices'] / max(counts['fine_vertices'], 1):.3f} of the fine vertices" if counts["fine_vertices"] else ""
        change = "" if name == "springs" else (f"; vs fine: peak {100 * (step.peak_pressure_mpa / fine.peak_pressure_mpa - 1):+.2f} %, "
                                               f"area {100 * (step.contact_area_mm2 / fine.contact_area_mm2 - 1):+.2f} %, "
                                               f"displacement {np.linalg.norm(step.displacement_mm - fine.displacement_mm) / np.linalg.norm(fine.displacement_mm) * 100:.2f} %")
        print(f"  {law:9s} {result.n_springs:6d} springs, {name:14s}: run {t:7.3f} s (median of {rounds}) = {t / base_time:5.2f}x springs, "
              f"iterations {sum(s.iterations for s in result.steps)}{size}; final peak {step.peak_pressure_mpa:.3f} MPa, area {step.contact_area_mm2:.1f} mm^2{change}", flush=True)


def cylinder_layer(nu: float, coarse_sizes: list[float], spring_mesh_mm: float | None) -> None:
    """The thin-layer campaign's base point on the bonded cylinder layer (2 mm, 333 N), DEM, fine vs
    coarse Pade; ``spring_mesh_mm``: the springs' mesh size (None: the scene's)."""
    import time

    from edem.pressure_metrics import regularised_peak_pressure_mpa
    from edem.scene import load_scene
    from edem.solver import run

    scene = load_scene("cylinder-layer", {"load.force_n": [0.0, 0.0, 333.0], "cartilage.poissons_ratio": nu, "geometry.plafond_gap_mm": 2.0,
                                          "cartilage.thickness_mm": 2.0, "cartilage.coupling": "thin-layer",
                                          **({} if spring_mesh_mm is None else {"geometry.mesh_size_mm": spring_mesh_mm})})
    points, triangles = scene.mobile.vertices_mm, scene.mobile.triangles[scene.spring_triangle]
    rows = {}
    for name, coarse in [("fine", None)] + [(f"coarse {c:g} mm", c) for c in coarse_sizes]:
        use_coarse(coarse)
        _COUNTS.update(coarse_vertices=0, fine_vertices=0)
        started = time.perf_counter()
        result = run(scene, "dem")
        elapsed = time.perf_counter() - started
        step = result.steps[-1]
        peak = regularised_peak_pressure_mpa(points, triangles, step.pressure_mpa, at_points=False)
        share = _COUNTS["coarse_vertices"] / _COUNTS["fine_vertices"] if _COUNTS["fine_vertices"] else 1.0
        rows[name] = (float(np.linalg.norm(step.displacement_mm)), peak, step.contact_area_mm2, elapsed, share)
    use_coarse(None)
    d0, p0, a0, _, _ = rows["fine"]
    print(f"  cylinder layer 2 mm, 333 N, nu {nu:g}, {triangles.shape[0]} springs:")
    for name, (d, p, a, t, share) in rows.items():
        print(f"    {name:14s}: displacement {d:.5f} mm ({100 * (d / d0 - 1):+.2f} %), regularised peak {p:.4f} MPa ({100 * (p / p0 - 1):+.2f} %), "
              f"area {a:.2f} mm^2 ({100 * (a / a0 - 1):+.2f} %), DEM {t:.2f} s, smoothing space {share:.3f} of the fine vertices", flush=True)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--sizes", default="0.94,0.3", help="spring mesh sizes, mm")
    parser.add_argument("--laws", default="gap,threshold")
    parser.add_argument("--coarse", default="0.8,1.2", help="coarse space sizes (cube sides), mm")
    parser.add_argument("--nus", default="0.42,0.49", help="Poisson's ratios of the cylinder layer ('' to skip)")
    parser.add_argument("--layer-meshes", default="scene,0.3", help="the cylinder layer's spring mesh sizes, mm ('scene': its own)")
    args = parser.parse_args()
    coarse = [float(c) for c in args.coarse.split(",")]
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    for layer_mesh in args.layer_meshes.split(","):
        for nu in [float(v) for v in args.nus.split(",") if v]:
            cylinder_layer(nu, coarse, None if layer_mesh == "scene" else float(layer_mesh))
    for size in (float(s) for s in args.sizes.split(",") if s):
        for law in args.laws.split(","):
            stance(size, law, args.steps, args.rounds, coarse)
    print(f"load average {os.getloadavg()[0]:.1f}")
