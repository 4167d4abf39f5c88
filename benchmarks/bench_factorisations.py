"""The coupled layer's factorisations, each solver on the matrices a stance actually factors.

Runs the stances of ``bench_thin_layer`` (the idealised ankle, nu 0.45, EDEM, threshold and gap
laws, about 3k and 30k springs) with the coupled layer and, at every factorisation the bed asks
for, factors the same matrix by each candidate and solves one right-hand side, timing factor plus
solve:

- Pade (SPD, one fixed pattern per cell set): LAPACK's banded Cholesky in reverse Cuthill-McKee
  order as the bed uses it without cvxopt (refactoring only the trailing columns where it can;
  the run itself is kept on this path), the same from scratch, QDLDL's LDL^T (approximate
  minimum degree found at the pattern's first factorisation, then ``update``: the numbers only),
  SuperLU's symmetric mode, CHOLMOD through cvxopt if it is installed (the optional extra
  ``cholmod``, as the bed uses it, ``edem.sparse_factors.SupernodalCholesky``: the symbolic
  analysis once per pattern, counted in that pattern's first factorisation, then the numeric
  factorisation and one solve per factorisation), and CHOLMOD through cholespy if it is
  installed (no numeric-only refactorisation: analysis and factor at every call);
- two-pole (the indefinite block, whose pattern follows the contact set): the bed's solve (QDLDL,
  residual-checked: fresh on per-time-point cells, on the gap law's whole surface with its
  ordering kept while the contact stays within it, ``KeptOrderingLDL``) and SuperLU's symmetric
  mode with threshold pivoting on the same matrix.

Prints per size, law and solver the total and median milliseconds, the total against the banded
path's, and the largest relative residual |A x - b| / |b|. With ``--resolution r`` > 0 the gap
law also runs with the coarse smoothing space (``[cartilage] thin_layer_smoothing_resolution``).

    .venv/bin/python benchmarks/bench_factorisations.py [--steps 20] [--sizes 0.94,0.3] [--laws threshold,gap] [--resolution 3] [--symbols pade,two-pole]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as the command line runs (edem.cli.main), before numpy loads

import argparse  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402
import qdldl  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from bench_edem import stance_like_scene  # noqa: E402
from scipy.sparse.linalg import splu  # noqa: E402

import edem.sparse_factors as sparse_factors  # noqa: E402
import edem.thin_layer as thin_layer  # noqa: E402
from edem.beds import CoupledThinLayer, on_bed  # noqa: E402
from edem.raycast import RayCaster  # noqa: E402
from edem.solver import run  # noqa: E402

try:
    import cholespy
except ImportError:  # optional: CHOLMOD without numeric-only refactorisation
    cholespy = None


def timed(factor_and_solve, matrix: sp.csc_matrix, rhs: np.ndarray) -> tuple[float, float]:
    """(seconds, relative residual) of one factorisation and one solve."""
    start = time.perf_counter()
    x = factor_and_solve()
    seconds = time.perf_counter() - start
    return seconds, float(np.linalg.norm(matrix @ x - rhs) / np.linalg.norm(rhs))


def pade_candidates(banded, pattern, data: np.ndarray, rhs: np.ndarray, kept: dict) -> dict:
    """Each SPD solver on H + Z W Z^T with this pattern and data; ``banded``: the bed's
    ``OperatorPattern.factorise``; ``kept``: QDLDL's factor of the last pattern."""
    matrix = pattern.matrix(data)
    fresh = sparse_factors.OperatorPattern(pattern.indices, pattern.indptr, pattern.slots, pattern.q, pattern.whole_surface)
    fresh.__dict__["band"] = pattern.band  # the ordering is per pattern in both: only the factor is fresh

    def ldl():
        if kept.get("pattern") is pattern:
            kept["solver"].update(matrix)
        else:  # a new cell set: its ordering and elimination tree
            kept.update(pattern=pattern, solver=qdldl.Solver(matrix))
        return kept["solver"].solve(rhs)

    out = {
        "banded from scratch": timed(lambda: banded(fresh, data)(rhs), matrix, rhs),
        "qdldl, ordering kept": timed(ldl, matrix, rhs),
        "superlu": timed(lambda: splu(matrix, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True}).solve(rhs), matrix, rhs),
    }
    if sparse_factors.cholmod_module() is not None:

        def supernodal():
            if kept.get("cholmod pattern") is not pattern:  # a new cell set: its analysis (the ordering, the supernodes)
                kept.update({"cholmod pattern": pattern, "cholmod": sparse_factors.SupernodalCholesky(pattern.indices, pattern.indptr)})
            return kept["cholmod"].factorise(data)(rhs)  # the numbers only, then one solve

        out["cholmod (cvxopt), symbolic kept"] = timed(supernodal, matrix, rhs)
    if cholespy is not None:
        lower = sp.tril(matrix, format="csc")  # cholespy reads one triangle (the full matrix crashes it)

        def analysed_each_time():
            solver = cholespy.CholeskySolverD(matrix.shape[0], lower.indptr.astype(np.int32), lower.indices.astype(np.int32), lower.data,
                                              cholespy.MatrixType.CSC)
            x = np.zeros_like(rhs)
            solver.solve(rhs, x)
            return x

        out["cholmod (cholespy)"] = timed(analysed_each_time, matrix, rhs)
    return out


def bench(mesh_size_mm: float, law: str, n_steps: int, resolution: float, symbols: list[str]) -> None:
    base = stance_like_scene(mesh_size_mm, n_steps)
    caster = RayCaster(base.fixed.vertices_mm, base.fixed.triangles)
    cartilage = replace(base.cartilage, poissons_ratio=0.45, law=law, thickness_mm=2.0 if law != "threshold" else None)
    rng = np.random.default_rng(0)
    factorise, indefinite_solve = sparse_factors.OperatorPattern.factorise, thin_layer.indefinite_solve
    kept_factorise = sparse_factors.KeptOrderingLDL.factorise
    for symbol in symbols:
        figures: dict[str, list[tuple[float, float]]] = {}
        kept: dict = {}

        def record(name: str, figure: tuple[float, float]) -> None:
            figures.setdefault(name, []).append(figure)

        def pade(pattern, data):
            rhs = rng.standard_normal(pattern.n_vertices)
            holder = []
            record("banded, as the bed uses it", timed(lambda: holder.append(factorise(pattern, data)) or holder[0](rhs), pattern.matrix(data), rhs))
            for name, figure in pade_candidates(factorise, pattern, data, rhs, kept).items():
                record(name, figure)
            return holder[0]

        def indefinite(matrix):
            rhs = rng.standard_normal(matrix.shape[0])
            holder = []
            record("qdldl, checked (the bed's)", timed(lambda: holder.append(indefinite_solve(matrix)) or holder[0](rhs), matrix, rhs))
            record("superlu, threshold pivoting", timed(
                lambda: splu(matrix, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.1, options={"SymmetricMode": True}).solve(rhs), matrix, rhs))
            return holder[0]

        def kept_indefinite(ldl, data, spring_weight):
            matrix = ldl.stack.pattern.matrix(data).tocsc()
            rhs = rng.standard_normal(matrix.shape[0])
            holder = []
            record("qdldl, kept ordering (the bed's)", timed(lambda: holder.append(kept_factorise(ldl, data, spring_weight)) or holder[0](rhs), matrix, rhs))
            record("superlu, threshold pivoting", timed(
                lambda: splu(matrix, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.1, options={"SymmetricMode": True}).solve(rhs), matrix, rhs))
            return holder[0]

        # The bed's factorisations replayed on its banded path (CHOLMOD, which the bed takes for a
        # large whole surface where cvxopt is installed, is a row of its own).
        sparse_factors.OperatorPattern.factorise, thin_layer.indefinite_solve = pade, indefinite
        sparse_factors.KeptOrderingLDL.factorise = kept_indefinite
        uses_cholmod, sparse_factors.OperatorPattern.uses_cholmod = sparse_factors.OperatorPattern.uses_cholmod, False
        try:
            layer = on_bed(cartilage, CoupledThinLayer.coupling, thin_layer_symbol=symbol, thin_layer_smoothing_resolution=resolution)
            result = run(replace(base, cartilage=layer), "edem", caster=caster)
        finally:
            sparse_factors.OperatorPattern.factorise, thin_layer.indefinite_solve = factorise, indefinite_solve
            sparse_factors.KeptOrderingLDL.factorise = kept_factorise
            sparse_factors.OperatorPattern.uses_cholmod = uses_cholmod
        reference = sum(s for s, _ in next(iter(figures.values())))  # the bed's own path, the first recorded
        where = f"{law}{f' r{resolution:g}' if resolution else ''}"
        for name, rows in figures.items():
            seconds = [s for s, _ in rows]
            print(f"{where:9s} {result.n_springs:6d} springs, {symbol:8s} {name:32s}: {len(rows):3d} factorisations, total {1e3 * sum(seconds):8.1f} ms "
                  f"({sum(seconds) / reference:5.2f}x the bed's), median {1e3 * statistics.median(seconds):7.2f} ms, "
                  f"largest relative residual {max(r for _, r in rows):.1e}", flush=True)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20, help="time points of the stance")
    parser.add_argument("--sizes", default="0.94,0.3", help="mesh sizes in mm (0.94: about 3k springs, 0.3: about 30k)")
    parser.add_argument("--laws", default="threshold,gap")
    parser.add_argument("--resolution", type=float, default=3.0, help="the gap law also with this coarse smoothing resolution (0: not)")
    parser.add_argument("--symbols", default="pade,two-pole")
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    for size in (float(s) for s in args.sizes.split(",")):
        for law in args.laws.split(","):
            for resolution in (0.0, args.resolution) if law != "threshold" and args.resolution > 0.0 else (0.0,):
                bench(size, law, args.steps, resolution, args.symbols.split(","))
    print(f"load average {os.getloadavg()[0]:.1f}")
