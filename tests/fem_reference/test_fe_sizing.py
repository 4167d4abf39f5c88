"""Sizing an FE run before it is meshed (issue 13): counts against the built solid, and refusal."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from edem.cli import main
from edem.scene import load_scene
from fem_reference.sizing import ITERATIVE_FROM_DOFS, SAFETY, FESize, check_fits, direct_fits, estimate, memory_bytes, solid_size
from geometries.errors import InputError
from geometries.fe_solids import layer_solid


@pytest.mark.parametrize("mesh_size_mm", [2.0, 0.9, 0.45])
def test_solid_size_counts_the_cells_and_vertices_the_builder_makes(mesh_size_mm):
    """The layer solid of the flat-plates scene (a 10 x 10 grid, 200 triangles, 2 mm thick):
    cells exactly (3 tetrahedra per prism, 4^levels triangles, ceil(t / size) layers), vertices
    to within the boundary-vertex term a 'half the triangles' count leaves out (a grid of n x n
    cells has (n+1)^2 = n^2 + 2n + 1 vertices, the estimate n^2 + 1)."""
    mobile = load_scene(_flat_plates()).mobile
    solid = layer_solid(mobile, 2.0, mesh_size_mm)
    edge = float(np.mean(np.linalg.norm(np.diff(mobile.vertices_mm[mobile.triangles][:, [0, 1, 2, 0]], axis=1), axis=2)))
    cells, vertices = solid_size(mobile.n_triangles, edge, 2.0, mesh_size_mm, None)
    assert cells == len(solid.tets)
    n = math.isqrt(mobile.n_triangles // 2) * round(2 ** max(0, math.ceil(math.log2(edge / mesh_size_mm) - 1e-9)))
    layers = len(solid.points_mm) // (n + 1) ** 2
    assert abs(vertices - len(solid.points_mm)) <= (2 * n) * layers


def _flat_plates():
    from verification.campaign_model import SCENES_DIR

    return SCENES_DIR / "flat-plates.toml"


def test_dofs_per_element_and_the_direct_solver_below_its_threshold_while_its_memory_fits():
    """P1: 3 per vertex; P2: 3 per vertex and edge (edges ~ vertices + cells); TH adds a pressure
    per vertex. The LU is used below ITERATIVE_FROM_DOFS while its estimate times the safety
    factor fits the memory available, the Krylov solver past that for every element and from
    the threshold for P2 and Taylor-Hood (ITERATIVE_ELEMENTS)."""
    small = estimate(1000, 300, "P1", available_bytes=24e9)
    assert small.dofs == 900 and small.solver == "direct"
    assert estimate(1000, 300, "P2").dofs == 3 * (300 + 1300)
    assert estimate(1000, 300, "TH").dofs == 3 * (300 + 1300) + 300
    cells = 2_000  # about 7.6k P2 DOFs, below the threshold: the LU while it fits
    dofs = estimate(cells, cells // 5, "P2", available_bytes=100e9).dofs
    assert dofs < ITERATIVE_FROM_DOFS
    need = SAFETY * memory_bytes(dofs, "direct")
    assert estimate(cells, cells // 5, "P2", available_bytes=need).solver == "direct" and direct_fits(dofs, need)
    assert estimate(cells, cells // 5, "P2", available_bytes=need * 0.99).solver == "iterative" and not direct_fits(dofs, need * 0.99)
    # Taylor-Hood too: past the LU's memory its Krylov path is the Schur-complement field split
    assert estimate(cells, cells // 5, "TH", available_bytes=need * 0.99).solver == "iterative"
    # from the threshold on, the Krylov path whatever the memory
    big = estimate(300_000, 60_000, "P2", available_bytes=1e15)
    assert big.dofs >= ITERATIVE_FROM_DOFS and big.solver == "iterative"
    # ... for the p-multigrid's elements only: P1 keeps the LU wherever it fits
    big_p1 = estimate(300_000, 60_000, "P1", available_bytes=1e15)
    assert big_p1.dofs >= ITERATIVE_FROM_DOFS and big_p1.solver == "direct"
    # a forced solver is estimated as such, whatever fits
    assert estimate(cells, cells // 5, "P2", available_bytes=need * 0.99, linear_solver="direct").solver == "direct"
    assert estimate(1000, 300, "P1", available_bytes=24e9, linear_solver="iterative").solver == "iterative"
    # memory grows faster than the DOFs for the direct solver (LU fill), linearly for Krylov
    a, b = estimate(10_000, 2_000, "P1"), estimate(80_000, 16_000, "P1")
    assert b.memory_bytes > a.memory_bytes


def test_a_solve_that_does_not_fit_is_refused_naming_size_and_memory():
    size = FESize(cells=10**9, vertices=2 * 10**8, dofs=3 * 10**9, solver="iterative", memory_bytes=4e11)
    with pytest.raises(InputError) as err:
        check_fits(size, 0.01, lambda h: size, file="scene.toml", key="mesh_size_mm", available_bytes=8e9)
    text = str(err.value)
    assert "0.01 mm" in text and "400 GB" in text and "8 GB are available" in text and "scene.toml" in text
    check_fits(size, 0.01, lambda h: size, file=None, key="k", available_bytes=SAFETY * 4e11 + 1)  # fits: no error
    assert "Krylov" not in text  # already the iterative solver
    forced_lu = FESize(cells=10**6, vertices=2 * 10**5, dofs=3 * 10**6, solver="direct", memory_bytes=4e11)
    with pytest.raises(InputError, match="Krylov solver"):  # a forced LU that does not fit names the way out
        check_fits(forced_lu, 0.1, lambda h: forced_lu, file="scene.toml", key="linear_solver", available_bytes=8e9)


def test_edem_fe_with_a_tiny_mesh_size_exits_2_before_meshing(capsys):
    pytest.importorskip("dolfinx_solver")
    status = main(["fe", "ideal-standing", "--mesh-size", "0.01", "--out", "/nonexistent/never-written",
                   "--set", "geometry.cartilage=false", "--set", "cartilage.law=threshold"])
    err = capsys.readouterr().err
    assert status == 2
    assert "mesh size 0.01 mm" in err and "GB are available" in err and "Traceback" not in err


def test_the_suggested_mesh_size_builds_a_mesh_that_fits():
    """With the layers given (a study's in-plane level) every size short of the next halving of
    the triangles builds the same mesh: the suggestion must be one whose own estimate fits, the
    finest such within the search's 2 % step."""
    def size_at(mesh_size_mm):
        cells, vertices = solid_size(6000, 0.9, 1.4, mesh_size_mm, 2)  # the ideal ankle's talar surface, two layers
        return estimate(2 * cells, 2 * vertices, "P2", linear_solver="iterative")

    refused = size_at(0.35)  # M's triangles halved twice
    available = SAFETY * refused.memory_bytes * 0.9
    with pytest.raises(InputError) as err:
        check_fits(refused, 0.35, size_at, file="scene.toml", key="mesh_size_mm", available_bytes=available)
    suggested = float(re.search(r"e\.g\. ([0-9.]+) mm", str(err.value)).group(1))
    assert SAFETY * size_at(suggested).memory_bytes <= available  # the suggestion fits ...
    assert SAFETY * size_at(suggested / 1.03).memory_bytes > available  # ... and is the finest that does, to the step and rounding
    assert size_at(suggested).dofs < refused.dofs / 3  # the next halving, not the same mesh
