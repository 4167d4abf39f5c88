"""The thin-layer compliance operator against the bonded-layer closed forms: its symbols (edem.layer_symbols),
its factors (edem.sparse_factors), its coarse space (edem.coarse_space) and the operator (edem.thin_layer)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve
from support import grid_plate, periodic_grid

from edem.mechanics import confined_modulus_mpa
from edem.layer_symbols import (
    LAYER_SYMBOLS,
    TWO_POLE_MAX_KH,
    _definiteness_margin,
    exact_layer_compliance,
    pade_coefficients,
    pade_symbol,
    taylor_coefficients,
    two_pole_symbol,
)
from edem.sparse_factors import _dense_columns
from edem.thin_layer import SurfaceMesh, _corner_means, boundary_vertices, layer_compliance

E = 10.35
NUS = (0.0, 0.1, 0.3, 0.42, 0.45, 0.49, 0.499)


def test_taylor_coefficients_are_the_exact_compliance_series():
    # The series C G/h = c0 + c1 q^2 + c2 q^4 + O(q^6): at q = 0.02 the remainder of each
    # successive difference quotient is O(q^2) of the next coefficient (< 1e-3 relative).
    q = 0.02
    for nu in NUS:
        c0, c1, c2 = taylor_coefficients(nu)
        exact = exact_layer_compliance(np.array([q, 2 * q]), nu)
        assert c0 == pytest.approx(E / (2 * (1 + nu)) / confined_modulus_mpa(E, nu), rel=1e-12)  # G / E'
        # Richardson on two points removes the q^4 term: c1 to O(q^4).
        d1, d2 = (exact - c0) / np.array([q, 2 * q]) ** 2
        assert (4 * d1 - d2) / 3 == pytest.approx(c1, abs=1e-6)
        assert (d2 - d1) / (3 * q * q) == pytest.approx(c2, rel=1e-2, abs=1e-6)
    # Incompressible thin-layer law: c1 = 1/3 at nu = 1/2; c1 = 0 at nu = 1/4.
    assert taylor_coefficients(0.5)[1] == pytest.approx(1 / 3)
    assert taylor_coefficients(0.25)[1] == 0.0
    # Half-space limit at short waves: C G / h -> (1 - nu) / kh.
    assert exact_layer_compliance(np.array([40.0]), 0.3)[0] == pytest.approx(0.7 / 40.0, rel=1e-12)


@pytest.mark.parametrize("nu", NUS)
def test_pade_stays_within_its_stated_error_for_kh_up_to_1(nu):
    # Bounds stated in the module docstring (3 % at nu = 0, 1.5 % above 0.1).
    bound = 0.03 if nu < 0.1 else 0.015
    assert pade_symbol(nu).error_bound(nu) <= bound
    # ... and it is a real improvement on the independent springs from nu = 0.42 on.
    if nu >= 0.42:
        kh = np.linspace(1e-3, 1.0, 500)
        springs = np.abs(taylor_coefficients(nu)[0] / exact_layer_compliance(kh, nu) - 1).max()
        assert pade_symbol(nu).error_bound(nu) < 0.1 * springs


@pytest.mark.parametrize("symbol", tuple(LAYER_SYMBOLS))
@pytest.mark.parametrize("nu", (0.3, 0.42, 0.49, 0.499))
def test_sinusoidal_pressure_reproduces_the_discrete_symbol_to_round_off(nu, symbol):
    """p = cos(k.x) on a periodic right-triangle grid: w is the Bloch symbol exactly.

    Symbol (module docstring): w_c = c_loc p_c + sum_i sigma_i c_i Re[q_c l / eta_i e^{ik.x_c}]
    over the symbol's terms (c_i = |s_i| h / G), with the vertex load l = (A/3) sum_{6 cells at a
    vertex} e^{ik.(x_c - x_v)}, the P1 five-point symbol eta_i = mu + b_i h^2 (4 - 2 cos k_x s_g -
    2 cos k_y s_g) with mu the symbol of M = Q^T A Q and q_c the corner mean of the triangle.
    """
    n, spacing, h = 48, 0.25, 2.0
    mesh, centroid = periodic_grid(n, spacing)
    g = E / (2 * (1 + nu))
    model = LAYER_SYMBOLS[symbol](nu)
    for mode in ((1, 0), (3, 2), (6, 0)):
        k = 2 * np.pi * np.array(mode) / (n * spacing)
        p = np.cos(centroid[:, :2] @ k)
        layer = layer_compliance(mesh, np.arange(mesh.area_mm2.shape[0]), h, E, nu, symbol=model)
        w = layer.deflection(p * mesh.area_mm2)
        cell_offsets = np.array([[2, 1], [1, 2], [-1, 1], [-1, -2], [-2, -1], [1, -1]]) / 3 * spacing
        load = np.exp(1j * cell_offsets @ k).sum() / 3 * spacing**2 / 2
        corners_l = np.array([[-2, -1], [1, -1], [1, 2]]) / 3 * spacing
        corners_u = np.array([[-1, -2], [2, 1], [-1, 1]]) / 3 * spacing
        q_l, q_u = np.exp(1j * corners_l @ k).mean(), np.exp(1j * corners_u @ k).mean()
        q_cell = np.repeat([q_l, q_u], n * n)
        # M = Q^T A Q: the six cells at a vertex, L U L L U U in the order of cell_offsets.
        q_around = np.array([q_l, q_u, q_l, q_l, q_u, q_u])
        mass = (spacing**2 / 2 / 3 * q_around * np.exp(1j * cell_offsets @ k)).sum()
        expected = model.local * h / g * p
        for strength, b in zip(model.strengths, model.screenings):
            eta = mass + b * h * h * (4 - 2 * np.cos(k[0] * spacing) - 2 * np.cos(k[1] * spacing))
            expected = expected + strength * h / g * np.real(q_cell * load / eta * np.exp(1j * centroid[:, :2] @ k))
        np.testing.assert_allclose(w, expected, atol=1e-12 * np.abs(expected).max())


@pytest.mark.parametrize("symbol", tuple(LAYER_SYMBOLS))
@pytest.mark.parametrize("nu", (0.3, 0.49))
def test_discrete_symbol_converges_to_the_continuum_symbol_at_second_order(nu, symbol):
    """The same wave k (kh = 3.1 and 6.3, where the two-pole's short-range term matters) on grids
    of spacing s and s/2: the discrete ratio w/p approaches the continuum symbol with an error
    that falls 4x per halving (P1 mass and five-point Laplacian, both O((k s)^2)); 4 +- 20 % for
    the O((k s)^4) remainder at k s <= 0.79. At kh <= 1 it is the exact layer within the symbol's
    bound plus that error."""
    h, length = 2.0, 12.0
    g = E / (2 * (1 + nu))
    model = LAYER_SYMBOLS[symbol](nu)
    for mode in (3, 6, 1):
        k = 2 * np.pi * mode / length
        errors = []
        for n in (48, 96):
            mesh, centroid = periodic_grid(n, length / n)
            p = np.cos(centroid[:, 0] * k)
            w = layer_compliance(mesh, np.arange(mesh.area_mm2.shape[0]), h, E, nu, symbol=model).deflection(p * mesh.area_mm2)
            lower = slice(0, n * n)
            ratio = w[lower] @ p[lower] / (p[lower] @ p[lower]) * g / h
            errors.append(ratio - model(k * h))
        if abs(errors[0]) > 1e-6 * model(k * h):  # (above round-off)
            assert errors[0] / errors[1] == pytest.approx(4.0, rel=0.2)
        if k * h <= 1.1:
            assert ratio == pytest.approx(exact_layer_compliance(k * h, nu), rel=model.error_bound(nu, 1.1) + abs(errors[1]) / model(k * h) + 1e-9)


def test_pade_symbol_is_the_pade_model():
    # local + s / (1 + b x) with local = a / b and s = -c1 / b is (e + a x) / (1 + b x).
    for nu in NUS:
        e, a, b = pade_coefficients(nu)
        x = np.linspace(0.0, 12.0, 97) ** 2
        np.testing.assert_allclose(pade_symbol(nu)(np.sqrt(x)), (e + a * x) / (1 + b * x), rtol=1e-12)


@pytest.mark.parametrize("nu", (-0.5, 0.0, 0.1, 0.25, 0.3, 0.42, 0.45, 0.49, 0.499, 0.4999))
def test_two_pole_symbol_follows_the_exact_compliance_up_to_kh_12(nu):
    """C(0) = G/E' and the thin-layer coefficient c1 exactly; within the bound the module
    docstring states over 0 <= kh <= 12 (4.5 % for 0 <= nu < 1/2, largest measured 4.2 % at
    nu -> 1/2; 5 % down to nu = -0.5), where the Pade levels off at a/b and is off by a factor
    of 2-5; definite with at least half the margin of its own limits (``_definiteness_margin``)."""
    model = two_pole_symbol(nu)
    c0, c1, _ = taylor_coefficients(nu)
    assert model(0.0) == pytest.approx(c0, rel=1e-12)
    slope = -sum(s * b for s, b in zip(model.strengths, model.screenings))
    assert slope == pytest.approx(c1, abs=1e-12)
    assert model.error_bound(nu, TWO_POLE_MAX_KH) <= (0.045 if nu >= 0.0 else 0.05)
    if nu >= 0.0:
        assert pade_symbol(nu).error_bound(nu, TWO_POLE_MAX_KH) > 20 * model.error_bound(nu, TWO_POLE_MAX_KH)
    margin = _definiteness_margin(np.array([model.local]), np.array([model.strengths]), np.array([model.screenings]))[0]
    assert margin >= 0.5 * min(model.local, c0)
    # the bulge term vanishes on a free edge, the sag term is natural there
    assert model.dirichlet == tuple(s < 0 for s in model.strengths)


def test_definiteness_margin_is_the_smallest_value_of_the_terms():
    # Against a brute-force minimum of local + g(x) over x in [0, 1e8] (log grid, 2e5 points):
    # the grid resolves the stationary point to ~1e-9 relative.
    rng = np.random.default_rng(5)
    s = rng.normal(0.0, 1.0, (200, 2))
    b = np.exp(rng.uniform(np.log(1e-3), np.log(1e2), (200, 2)))
    local = rng.uniform(0.0, 2.0, 200)
    x = np.concatenate([[0.0], np.geomspace(1e-6, 1e8, 200001)])
    g = s[:, :1] / (1 + b[:, :1] * x) + s[:, 1:] / (1 + b[:, 1:] * x)
    brute = local + np.minimum(g.min(axis=1), 0.0)
    np.testing.assert_allclose(_definiteness_margin(local, s, b), brute, rtol=1e-6, atol=1e-9)


def test_small_poisson_ratio_and_long_waves_give_independent_springs():
    n, spacing, h = 32, 0.5, 2.0
    mesh, centroid = periodic_grid(n, spacing)
    cells = np.arange(mesh.area_mm2.shape[0])
    p = 1.0 + 0.5 * np.cos(centroid[:, 0] * 2 * np.pi / (n * spacing))
    # nu = 0: c1 = 0, the layer is the bed of independent springs h / E' exactly.
    w = layer_compliance(mesh, cells, h, E, 0.0).deflection(p * mesh.area_mm2)
    np.testing.assert_allclose(w, h * p / confined_modulus_mpa(E, 0.0), rtol=1e-13)
    # Long waves at nu = 0.45: the deviation from h p / E' is the first Taylor term,
    # (c1 / c0) (kh)^2 on the cosine part (at its trough, where p = 0.5 and the cosine 0.5);
    # 5 % above it for the O((kh)^4) and the mesh terms. At kh = 0.785 it is far larger.
    c0, c1, _ = taylor_coefficients(0.45)
    deviation = []
    for scale in (1.0, 16.0):
        big, cen = periodic_grid(n, spacing * scale)
        kh = 2 * np.pi / (n * spacing * scale) * h
        pk = 1.0 + 0.5 * np.cos(cen[:, 0] * kh / h)
        w = layer_compliance(big, cells, h, E, 0.45).deflection(pk * big.area_mm2)
        deviation.append(np.abs(w / (h * pk / confined_modulus_mpa(E, 0.45)) - 1).max())
    assert deviation[1] <= 1.05 * c1 / c0 * kh**2
    assert deviation[0] > 100 * deviation[1]


@pytest.mark.parametrize("symbol", tuple(LAYER_SYMBOLS))
def test_flat_plate_under_uniform_pressure_deflects_uniformly(symbol):
    # A plate without free edges (periodic): K 1 = 0 and Q 1 = 1 make a uniform pressure's
    # deflection h p / E' at every spring, to round-off, at any nu (C(0) = G / E').
    mesh, _ = periodic_grid(24, 0.7)
    cells = np.arange(mesh.area_mm2.shape[0])
    for nu in NUS:
        w = layer_compliance(mesh, cells, 2.0, E, nu, symbol=LAYER_SYMBOLS[symbol](nu)).deflection(1.5 * mesh.area_mm2)
        np.testing.assert_allclose(w, 2.0 * 1.5 / confined_modulus_mpa(E, nu), rtol=1e-10)


@pytest.mark.parametrize("symbol", tuple(LAYER_SYMBOLS))
def test_uniform_pressure_on_a_layer_of_varying_thickness_deflects_each_spring_by_h_p_over_e_conf(symbol):
    # S 1 = 1 for any h (module docstring): no lateral flow without a pressure gradient, so every
    # spring deflects by its own h p / E', to round-off (periodic grid: no free edge).
    mesh, centroid = periodic_grid(24, 0.7)
    cells = np.arange(mesh.area_mm2.shape[0])
    h = 1.5 + np.sin(centroid[:, 0] * 2 * np.pi / (24 * 0.7)) ** 2  # 1.5 .. 2.5 mm
    for nu in (0.1, 0.42, 0.499):
        w = layer_compliance(mesh, cells, h, E, nu, symbol=LAYER_SYMBOLS[symbol](nu)).deflection(2.0 * mesh.area_mm2)
        np.testing.assert_allclose(w, h * 2.0 / confined_modulus_mpa(E, nu), rtol=1e-9)


@pytest.mark.parametrize("symbol", tuple(LAYER_SYMBOLS))
def test_compliance_is_symmetric_positive_definite(symbol):
    """On a plate with free edges and varying thickness; for the two-pole symbol, whose bulge
    term vanishes on the edge and sag term does not, C - diag(margin h / (G A)) stays positive
    semidefinite (``_definiteness_margin``), to round-off."""
    plate = grid_plate(10.0, 10.0, 8)
    mesh = SurfaceMesh.from_surface(plate.vertices_mm, plate.triangles)
    cells = np.arange(plate.n_triangles)
    thickness = 1.0 + 0.1 * np.arange(cells.size) / cells.size  # varying h keeps the symmetry
    for nu in (0.1, 0.42, 0.499):
        model = LAYER_SYMBOLS[symbol](nu)
        layer = layer_compliance(mesh, cells, thickness, E, nu, symbol=model)
        c = np.column_stack([layer.deflection(col) for col in np.eye(cells.size)])
        np.testing.assert_allclose(c, c.T, atol=1e-12 * np.abs(c).max())
        margin = _definiteness_margin(np.array([model.local]), np.array([model.strengths + (0.0,) * (2 - len(model.strengths))]),
                                      np.array([model.screenings + (1.0,) * (2 - len(model.screenings))]))[0]
        floor = margin * thickness * 2 * (1 + nu) / E / mesh.area_mm2  # mm/N
        scaled = (c - np.diag(floor)) / np.sqrt(np.outer(floor, floor))
        assert margin > 0.0 and np.linalg.eigvalsh(0.5 * (scaled + scaled.T)).min() > -1e-9


def test_incompressible_flat_punch_has_the_thin_layer_parabolic_pressure():
    """Rigid flat circular punch (radius a = 10 h) pressed by delta into a layer at nu -> 1/2.

    Thin-layer law: lap p = -3 G delta / h^3 under the punch, so p is the paraboloid
    p0 - (3 G delta / 4 h^3) r^2. The Pade operator has the same interior curvature exactly (its
    e -> 0 interior equation is a h^2 lap p = -G delta with a = 1/3); the edge changes p0 only.
    Curvature from a least-squares paraboloid over r < a - 3h, within 3 % (mesh size h / 4 at
    kh up to ~1, the operator's O((k s)^2) error plus the fit's).
    """
    h, a, delta, nu = 1.0, 10.0, 1e-3, 0.4999
    plate = grid_plate(36.0, 36.0, 144)
    mesh = SurfaceMesh.from_surface(plate.vertices_mm, plate.triangles)
    centroid = plate.centroids_mm
    r = np.linalg.norm(centroid[:, :2], axis=1)
    cells = np.arange(plate.n_triangles)
    layer = layer_compliance(mesh, cells, h, E, nu)
    inside = np.flatnonzero(r < a)
    # Contact: w = delta on the punch, f = 0 outside. With z = H^-1 Z f:
    # local f_I + sigma Z_I^T z = delta, H z - Z_I f_I = 0.
    (term,) = layer.terms
    zi = term.z[:, inside]
    system = sp.bmat([[sp.diags(layer.local_mm_per_n[inside]), term.sigma * zi.T], [-zi, term.h]]).tocsc()
    solution = spsolve(system, np.concatenate([np.full(inside.size, delta), np.zeros(term.h.shape[0])]))
    pressure = solution[: inside.size] / mesh.area_mm2[inside]
    g = E / (2 * (1 + nu))
    core = r[inside] < a - 3 * h
    fit = np.linalg.lstsq(np.column_stack([np.ones(core.sum()), r[inside][core] ** 2]), pressure[core], rcond=None)[0]
    assert -fit[1] == pytest.approx(3 * g * delta / (4 * h**3), rel=0.03)
    assert np.all(pressure > 0)


@pytest.mark.parametrize("path", ["banded", "sparse LU", "cholmod"])
def test_coupled_factor_solves_to_round_off_on_every_path(path, monkeypatch):
    """(sigma H + Z diag(x) Z^T) x = b through the banded Cholesky, the sparse LU and CHOLMOD (the
    optional extra; its bar lowered so that it takes this small whole-surface pattern).

    Residual against the assembled matrix within 1e-11 of |A| |x|: round-off (2e-16) times the
    matrix's condition, which for these operators stays below about 1e3 (mass plus a Laplacian
    at kh ~ 1 on the mesh scale), times a safety factor of 50. Also checks the band layout (or
    CHOLMOD's symbolic analysis) reused by a second factorisation with other weights on the same
    pattern.
    """
    import edem.sparse_factors as sparse_factors

    if path == "sparse LU":
        monkeypatch.setattr(sparse_factors, "MAX_BANDED_HALF_WIDTH", -1)
    if path == "cholmod":
        pytest.importorskip("cvxopt")
        monkeypatch.setattr(sparse_factors, "CHOLMOD_MIN_BAND_WORK", 0.0)
    else:
        monkeypatch.setattr(sparse_factors, "cholmod_module", lambda: None)
    plate = grid_plate(10.0, 10.0, 12)
    mesh = SurfaceMesh.from_surface(plate.vertices_mm, plate.triangles)
    cells = np.arange(plate.n_triangles)
    layer = layer_compliance(mesh, cells, 1.0 + 0.2 * (cells % 5) / 5, E, 0.49)
    (term,) = layer.terms
    rng = np.random.default_rng(3)
    # The contact solve's weights: 1 / local compliance on the springs in contact, 0 elsewhere.
    for active in (np.ones(cells.size, bool), rng.uniform(size=cells.size) < 0.4):
        weight = np.where(active, 1.0 / layer.local_mm_per_n, 0.0)
        matrix = term.sigma * term.h + layer.z @ sp.diags(weight) @ layer.z.T
        rhs = rng.standard_normal((matrix.shape[0], 2))
        x = layer.factorise_coupled(weight)(rhs)
        scale = abs(matrix).max() * np.abs(x).max()
        assert np.abs(matrix @ x - rhs).max() <= 1e-11 * scale
    assert term.pattern.uses_cholmod == (path == "cholmod")
    assert (term.pattern.band[3] <= sparse_factors.MAX_BANDED_HALF_WIDTH) == (path != "sparse LU")


def test_cholmod_takes_the_whole_surface_past_its_bar_and_matches_the_banded_factor(monkeypatch):
    """CHOLMOD (the optional extra) factors the whole surface's pattern where the banded work
    n w^2 reaches CHOLMOD_MIN_BAND_WORK and never a part of the surface (a cell set the run does
    not keep); its solves equal the banded factor's to round-off (both backward stable: within
    2 cond(A) eps, cond below 1e3 here (see above), times 50), a solve whose numbers the shared
    factor no longer holds (another factorisation came since) still solves its own matrix, and a
    matrix that is not positive definite is a SolverError."""
    pytest.importorskip("cvxopt")
    import edem.sparse_factors as sparse_factors
    from geometries.errors import SolverError

    plate = grid_plate(10.0, 10.0, 12)
    mesh = SurfaceMesh.from_surface(plate.vertices_mm, plate.triangles)
    cells = np.arange(plate.n_triangles)
    whole = mesh.operator_pattern(cells)
    n, width = whole.n_vertices, whole.band[3]
    monkeypatch.setattr(sparse_factors, "CHOLMOD_MIN_BAND_WORK", float(n * width * width))
    assert whole.uses_cholmod and not mesh.operator_pattern(cells[: cells.size // 2]).uses_cholmod
    monkeypatch.setattr(sparse_factors, "CHOLMOD_MIN_BAND_WORK", float(n * width * width) + 1.0)
    assert not mesh.operator_pattern(cells).uses_cholmod
    layer = layer_compliance(mesh, cells, 1.0 + 0.2 * (cells % 5) / 5, E, 0.49)
    (term,) = layer.terms
    rng = np.random.default_rng(8)
    data = [term.coupled_data(np.where(rng.uniform(size=cells.size) < 0.5, 1.0 / layer.local_mm_per_n, 0.0)) for _ in range(2)]
    rhs = rng.standard_normal((n, 3))
    supernodal = sparse_factors.SupernodalCholesky(term.pattern.indices, term.pattern.indptr)
    first = supernodal.factorise(data[0])
    second = supernodal.factorise(data[1])  # the factor object now holds the second matrix
    for values, solve in ((data[0], first), (data[1], second), (data[0], first)):
        banded = sparse_factors.OperatorPattern(term.pattern.indices, term.pattern.indptr, term.pattern.slots, term.pattern.q)
        expected = banded.factorise(values)(rhs)
        assert np.abs(solve(rhs) - expected).max() <= 50 * 2e3 * np.finfo(float).eps * np.abs(expected).max()
        assert np.abs(solve(rhs[:, 0]) - expected[:, 0]).max() <= 50 * 2e3 * np.finfo(float).eps * np.abs(expected).max()
    with pytest.raises(SolverError, match="not positive definite"):
        supernodal.factorise(-data[0])


def test_two_term_factor_solves_the_indefinite_block_to_round_off():
    """(sigma H + Z diag(x) Z^T) x = b for the two-pole symbol's two terms (a block of opposite
    signs, factored by SuperLU): residual within 1e-11 of |A| |x| (round-off times the blocks'
    condition, below about 1e3 here, with a safety factor of 50, as for one term), and the forces
    it gives on a contact set satisfy w = C f there: C_II f_I = d_I to round-off."""
    plate = grid_plate(10.0, 10.0, 12)
    mesh = SurfaceMesh.from_surface(plate.vertices_mm, plate.triangles)
    cells = np.arange(plate.n_triangles)
    layer = layer_compliance(mesh, cells, 1.0 + 0.2 * (cells % 5) / 5, E, 0.49, symbol=two_pole_symbol(0.49))
    assert [t.sigma for t in layer.terms] == [1.0, -1.0]
    rng = np.random.default_rng(4)
    active = rng.uniform(size=cells.size) < 0.5
    weight = np.where(active, 1.0 / layer.local_mm_per_n, 0.0)
    matrix = sp.block_diag([t.sigma * t.h for t in layer.terms]) + layer.z @ sp.diags(weight) @ layer.z.T
    rhs = rng.standard_normal((matrix.shape[0], 2))
    x = layer.factorise_coupled(weight)(rhs)
    assert np.abs(matrix @ x - rhs).max() <= 1e-11 * abs(matrix).max() * np.abs(x).max()
    # Woodbury: f_I = Lam (d_I - Z_I^T z), (sigma H + Z_I Lam Z_I^T) z = Z_I Lam d_I
    d = np.where(active, rng.uniform(0.01, 0.02, cells.size), 0.0)
    z = layer.factorise_coupled(weight)(layer.z @ (weight * d))
    f = weight * (d - layer.z.T @ z)
    w = layer.deflection(f)
    np.testing.assert_allclose(w[active], d[active], rtol=0.0, atol=1e-10 * d.max())


def test_two_pole_block_ldlt_agrees_with_pivoted_lu_within_its_condition(monkeypatch):
    """The two-pole's indefinite block, factored by QDLDL's LDL^T without SuperLU, solves to the
    same x as SuperLU's pivoted LU: both are accepted at a normwise backward error of at most
    V eps, so each is within cond(A) V eps of the exact solution (the forward-error bound of a
    backward-stable solve) and they differ by at most twice that."""
    import edem.sparse_factors as sparse_factors
    from scipy.sparse.linalg import splu

    plate = grid_plate(10.0, 10.0, 12)
    mesh = SurfaceMesh.from_surface(plate.vertices_mm, plate.triangles)
    cells = np.arange(plate.n_triangles)
    layer = layer_compliance(mesh, cells, 1.0 + 0.2 * (cells % 5) / 5, E, 0.49, symbol=two_pole_symbol(0.49))
    rng = np.random.default_rng(7)
    weight = np.where(rng.uniform(size=cells.size) < 0.5, 1.0 / layer.local_mm_per_n, 0.0)
    matrix = (sp.block_diag([t.sigma * t.h for t in layer.terms]) + layer.z @ sp.diags(weight) @ layer.z.T).tocsc()
    pivoted = []
    monkeypatch.setattr(sparse_factors, "splu", lambda *a, **k: pivoted.append(1) or splu(*a, **k))
    rhs = rng.standard_normal((matrix.shape[0], 3))
    x = layer.factorise_coupled(weight)(rhs)
    assert not pivoted  # the LDL^T's own solve was accepted
    reference = splu(matrix, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.1, options={"SymmetricMode": True}).solve(rhs)
    bound = 2.0 * np.linalg.cond(matrix.toarray(), np.inf) * matrix.shape[0] * np.finfo(float).eps
    assert np.abs(x - reference).max() <= bound * np.abs(reference).max()


def test_two_pole_refactors_on_its_kept_ordering_while_the_contact_stays_within_it(monkeypatch):
    """The two-pole's stacked block on the whole surface keeps its LDL^T ordering (found for the
    springs in contact and ORDERING_RINGS rings around them) while the springs in contact stay
    among those: a contact set that lost half its springs is refactored on it (no new ordering),
    one with a spring far outside finds a new one; every solve, also the first factor's after the
    others came (its numbers are put back), is the LDL^T's own (the check sends none to SuperLU)
    with a residual within 1e-11 of |A| |x| (round-off times the blocks' condition, below about
    1e3 here, with a safety factor of 50, as for a fresh factor)."""
    import edem.sparse_factors as sparse_factors

    plate = grid_plate(10.0, 10.0, 12)
    mesh = SurfaceMesh.from_surface(plate.vertices_mm, plate.triangles)
    cells = np.arange(plate.n_triangles)
    layer = layer_compliance(mesh, cells, 1.0 + 0.2 * (cells % 5) / 5, E, 0.49, symbol=two_pole_symbol(0.49))
    assert layer.stacked and not layer.definite
    orderings, pivoted = [], []
    found, splu = sparse_factors._Ordering.__init__, sparse_factors.splu
    monkeypatch.setattr(sparse_factors._Ordering, "__init__", lambda self, *a: orderings.append(1) or found(self, *a))
    monkeypatch.setattr(sparse_factors, "splu", lambda *a, **k: pivoted.append(1) or splu(*a, **k))
    centre = np.linalg.norm(mesh.vertices_mm[mesh.triangles].mean(axis=1)[:, :2] - 5.0, axis=1)
    rng = np.random.default_rng(11)
    contact = centre < 3.0
    fewer = contact & (rng.uniform(size=cells.size) < 0.5)
    beyond = fewer.copy()
    beyond[np.argmax(centre)] = True  # a corner spring, more than two rings outside the disc
    solves = []
    for springs, new_orderings in ((contact, 1), (fewer, 0), (beyond, 1)):
        before = len(orderings)
        weight = np.where(springs, 1.0 / layer.local_mm_per_n, 0.0)
        solves.append((weight, layer._factorise(weight)))
        assert len(orderings) - before == new_orderings
    rhs = rng.standard_normal((layer.z.shape[0], 2))
    for weight, solve in solves[::-1]:  # the last factor first: the earlier ones put their numbers back
        matrix = sp.block_diag([t.sigma * t.h for t in layer.terms]) + layer.z @ sp.diags(weight) @ layer.z.T
        x = solve(rhs)
        assert np.abs(matrix @ x - rhs).max() <= 1e-11 * abs(matrix).max() * np.abs(x).max()
    assert not pivoted  # every LDL^T solve was accepted (none fell back to SuperLU)


def test_indefinite_solve_pivots_where_diagonal_pivots_would_grow():
    """The 4 x 4 tridiagonal matrix with ones beside a diagonal d = 1e-12 is well conditioned
    (cond_inf = 4) but every diagonal pivot order starts on d, so an LDL^T without pivoting grows
    by 1/d (QDLDL's own answer is off by 3e-5); the checked solve sees the backward error and
    solves by SuperLU's pivoted LU instead: within cond(A) n eps of numpy's dense LU, twice over
    (both backward stable)."""
    from edem.sparse_factors import indefinite_solve

    n, d = 4, 1e-12
    dense = np.diag(np.full(n, d)) + np.diag(np.ones(n - 1), 1) + np.diag(np.ones(n - 1), -1)
    rhs = np.array([1.0, -2.0, 3.0, -4.0])
    x = indefinite_solve(sp.csc_matrix(dense))(rhs)
    exact = np.linalg.solve(dense, rhs)
    assert np.abs(x - exact).max() <= 2.0 * np.linalg.cond(dense, np.inf) * n * np.finfo(float).eps * np.abs(exact).max()


@pytest.mark.parametrize("symbol", ["pade", "two-pole"])
def test_a_few_changed_springs_reuse_the_factor_and_still_solve_to_round_off(symbol, monkeypatch):
    """The active-set iteration's next matrix differs in a few springs' weights: the kept factor,
    corrected by the Woodbury identity, solves it within the same 1e-11 of |A| |x| as a fresh
    factor (round-off times a condition below about 1e3, safety factor 50; the k x k capacitance
    adds a condition of the same order), with no new factorisation; the same weights again reuse
    the factor as it is; more than the layer's ``low_rank_max`` changed springs refactor."""
    import edem.thin_layer as thin_layer

    plate = grid_plate(10.0, 10.0, 12)
    mesh = SurfaceMesh.from_surface(plate.vertices_mm, plate.triangles)
    cells = np.arange(plate.n_triangles)
    layer = layer_compliance(mesh, cells, 1.0 + 0.2 * (cells % 5) / 5, E, 0.49, symbol=LAYER_SYMBOLS[symbol](0.49))
    factored = []
    fresh = thin_layer.LayerCompliance._factorise
    monkeypatch.setattr(thin_layer.LayerCompliance, "_factorise", lambda self, w: factored.append(1) or fresh(self, w))
    rng = np.random.default_rng(5)
    active = rng.uniform(size=cells.size) < 0.5
    layer.factorise_coupled(np.where(active, 1.0 / layer.local_mm_per_n, 0.0))
    assert len(factored) == 1
    for n_changed, refactors in ((layer.low_rank_max, 0), (0, 0), (3 * layer.low_rank_max, 1)):
        active = active.copy()
        active[rng.choice(cells.size, n_changed, replace=False)] ^= True  # springs entering and leaving
        weight = np.where(active, 1.0 / layer.local_mm_per_n, 0.0)
        before = len(factored)
        # A layer rebuilt on the same operators (the next time point) shares the kept factor.
        layer = layer_compliance(mesh, cells, 1.0 + 0.2 * (cells % 5) / 5, E, 0.49, symbol=LAYER_SYMBOLS[symbol](0.49))
        x_solve = layer.factorise_coupled(weight)
        assert len(factored) - before == refactors
        matrix = sp.block_diag([t.sigma * t.h for t in layer.terms]) + layer.z @ sp.diags(weight) @ layer.z.T
        rhs = rng.standard_normal((matrix.shape[0], 3))
        for b in (rhs, rhs[:, 0]):  # several right-hand sides and one
            x = x_solve(b)
            assert np.abs(matrix @ x - b).max() <= 1e-11 * abs(matrix).max() * np.abs(x).max()


def test_boundary_of_a_cell_set_is_the_boundary_of_its_triangles():
    """The mesh's numbered edges give the same boundary vertices as sorting the cells' edges."""
    plate = grid_plate(10.0, 10.0, 12)
    mesh = SurfaceMesh.from_surface(plate.vertices_mm, plate.triangles)
    rng = np.random.default_rng(6)
    for size in (1, 7, plate.n_triangles // 3, plate.n_triangles):
        cells = np.sort(rng.choice(plate.n_triangles, size, replace=False))
        expected = boundary_vertices(mesh.triangles[cells], mesh.free_edge_vertex.shape[0])
        np.testing.assert_array_equal(mesh.boundary_of(cells), expected)
        assert expected.any()  # a finite patch always has a boundary


def test_a_band_factor_refactored_from_the_first_changed_column_equals_a_fresh_one():
    """Consecutive banded factorisations on one pattern whose matrices differ from band column k
    on (springs changing state in the last third of the band order, as a contact edge does): the
    factor's columns before k are kept bitwise, and the factor equals a fresh factorisation within
    1e-13 of its largest entry (round-off of the trailing columns' other summation order: about
    the half-bandwidth, 20 here, times 2e-16, with a safety factor of 20); the same matrix again
    reuses the factor; the solves through it match the assembled matrix to round-off (1e-11 of
    |A| |x|, as for the fresh factor)."""
    plate = grid_plate(10.0, 10.0, 20)
    mesh = SurfaceMesh.from_surface(plate.vertices_mm, plate.triangles)
    cells = np.arange(plate.n_triangles)
    layer = layer_compliance(mesh, cells, 1.0 + 0.2 * (cells % 5) / 5, E, 0.45)
    (term,) = layer.terms
    pattern = term.pattern
    order, lower, flat, width = pattern.band
    n = order.size
    position = np.empty(n, np.int64)
    position[order] = np.arange(n)
    first_corner = np.minimum.reduceat(position[pattern.q.indices], pattern.q.indptr[:-1])
    # (a spring with every corner on the free edge has no row in the matrix: left out)
    late = np.flatnonzero((first_corner >= 2 * n // 3) & (np.diff(pattern.q.indptr) > 0))
    assert late.size > 10
    weight = np.where(cells % 2 == 0, 1.0 / layer.local_mm_per_n, 0.0)
    pattern.factorise(term.coupled_data(weight))
    entries, before = pattern.last_factor
    weight[late[::3]] = np.where(weight[late[::3]] > 0.0, 0.0, 1.0 / layer.local_mm_per_n[late[::3]])
    data = term.coupled_data(weight)
    solve = pattern.factorise(data)
    factor = pattern.last_factor[1]
    start = int(flat[np.flatnonzero(data[lower] != entries)].min()) // (width + 1)
    assert start >= n // 2
    np.testing.assert_array_equal(factor[:, :start], before[:, :start])
    pattern.factorise(data)
    assert pattern.last_factor[1] is factor
    pattern.last_factor = None
    fresh = pattern.factorise(data)
    assert np.abs(factor - pattern.last_factor[1]).max() <= 1e-13 * np.abs(factor).max()
    rhs = np.random.default_rng(9).standard_normal((n, 2))
    matrix = pattern.matrix(data)
    x = solve(rhs)
    assert np.abs(matrix @ x - rhs).max() <= 1e-11 * abs(matrix).max() * np.abs(x).max()
    np.testing.assert_allclose(x, fresh(rhs), rtol=0.0, atol=1e-12 * np.abs(x).max())


def test_a_cell_sets_pattern_restricted_from_the_surfaces_is_the_assembly_of_its_corner_pairs():
    """The operator pattern of a cell set, cut from the whole surface's (``surface_pairs``), sums
    per-pair values into the same matrix as adding them pair by pair at the cells' kept vertices
    (off the free edge, and off the cells' own boundary where the layer ends there), stores no
    pair the cells lack (a structural zero would widen the band) and keeps the vertices in the
    surface's order; Q is the corner mean on those vertices. For cell sets with holes, the whole
    surface and a single triangle, on a plate with a free edge, for every boundary option."""
    plate = grid_plate(10.0, 10.0, 12)
    mesh = SurfaceMesh.from_surface(plate.vertices_mm, plate.triangles)
    n_v = mesh.free_edge_vertex.shape[0]
    rng = np.random.default_rng(11)
    for size in (1, 40, plate.n_triangles // 2, plate.n_triangles):
        cells = np.sort(rng.choice(plate.n_triangles, size, replace=False))
        tri = mesh.triangles[cells]
        for edge_at_cells, dirichlet in ((False, True), (True, True), (True, False), (False, False)):
            mesh.memo.clear()
            pattern = mesh.operator_pattern(cells, edge_at_cells, dirichlet)
            free = np.zeros(n_v, bool) if not dirichlet else mesh.free_edge_vertex | (mesh.boundary_of(cells) if edge_at_cells else False)
            kept = np.zeros(n_v, bool)
            kept[tri] = True
            kept &= ~free
            vertices = np.flatnonzero(kept)  # the surface's order
            number = np.full(n_v, -1)
            number[vertices] = np.arange(vertices.size)
            values = rng.uniform(1.0, 2.0, (cells.size, 9))
            expected = np.zeros((vertices.size, vertices.size))
            touched = np.zeros((vertices.size, vertices.size), bool)
            for pair in range(9):
                i, j = number[tri[:, pair // 3]], number[tri[:, pair % 3]]
                inside = (i >= 0) & (j >= 0)
                np.add.at(expected, (i[inside], j[inside]), values[inside, pair])
                touched[i[inside], j[inside]] = True
            matrix = pattern.matrix(pattern.sum_at_slots(values))
            # Round-off: the same nine values per entry at most, summed in another order.
            np.testing.assert_allclose(matrix.toarray(), expected, rtol=1e-15, atol=0)
            assert matrix.nnz == touched.sum()
            q = np.zeros((cells.size, vertices.size))
            for corner in range(3):
                inside = number[tri[:, corner]] >= 0
                q[np.flatnonzero(inside), number[tri[inside, corner]]] += 1.0 / 3.0
            np.testing.assert_array_equal(pattern.q.toarray(), q)
            assert pattern.q.has_canonical_format  # sorted rows: Z^T's products sum in the vertices' order


def test_corner_means_add_up_a_corner_twice_and_give_the_csr_rows_of_z():
    """Q built directly in CSR form (``_corner_means``) is the corner mean, canonical, also where a
    triangle names a vertex twice (its weights add up) or has corners off the space (-1); the
    dense columns of chosen rows of a CSR matrix (``_dense_columns``) are those rows."""
    corners = np.array([[4, 0, 2], [1, -1, 3], [2, 2, 0], [-1, -1, -1], [3, 1, 4]])
    expected = np.zeros((5, 5))
    for t, row in enumerate(corners):
        for v in row[row >= 0]:
            expected[t, v] += 1.0 / 3.0
    for rows in (corners, corners[[0, 1, 3, 4]]):  # with and without the repeated vertex
        q = _corner_means(rows, 5)
        np.testing.assert_array_equal(q.toarray(), expected[[0, 1, 2, 3, 4] if rows.shape[0] == 5 else [0, 1, 3, 4]])
        assert q.has_canonical_format
    matrix = sp.random(40, 30, density=0.1, random_state=np.random.default_rng(2), format="csr")
    chosen = np.array([7, 0, 39, 7, 12])
    np.testing.assert_array_equal(_dense_columns(matrix, chosen), matrix[chosen].toarray().T)


def test_a_layer_on_the_same_cells_and_thickness_is_built_once():
    """The gap laws' layer keeps its cells and thickness over a run: the second call returns the
    kept compliance; another thickness builds a new one, equal to a build on a fresh mesh."""
    plate = grid_plate(10.0, 10.0, 8)
    mesh = SurfaceMesh.from_surface(plate.vertices_mm, plate.triangles)
    cells = np.arange(plate.n_triangles)
    first = layer_compliance(mesh, cells, np.full(cells.size, 2.0), E, 0.45)
    assert layer_compliance(mesh, cells, np.full(cells.size, 2.0), E, 0.45) is first
    thicker = layer_compliance(mesh, cells, np.full(cells.size, 2.5), E, 0.45)
    assert thicker is not first
    fresh = layer_compliance(SurfaceMesh.from_surface(plate.vertices_mm, plate.triangles), cells, np.full(cells.size, 2.5), E, 0.45)
    force = np.linspace(0.0, 1.0, cells.size)
    np.testing.assert_array_equal(thicker.deflection(force), fresh.deflection(force))
    assert layer_compliance(mesh, cells, np.full(cells.size, 2.5), E, 0.3) is not thicker  # and another material


# --------------------------------------------------------------------------- the coarse smoothing space


def sphere(n_points: int, radius_mm: float) -> SurfaceMesh:
    """A closed triangulated sphere (no free edge): the hull of a Fibonacci lattice."""
    from scipy.spatial import ConvexHull

    k = np.arange(n_points) + 0.5
    z = 1.0 - 2.0 * k / n_points
    phi = np.pi * (1.0 + 5.0**0.5) * k
    points = radius_mm * np.column_stack([np.sqrt(1.0 - z * z) * np.cos(phi), np.sqrt(1.0 - z * z) * np.sin(phi), z])
    return SurfaceMesh.from_surface(points, ConvexHull(points).simplices)


def plate_mesh(n: int) -> SurfaceMesh:
    plate = grid_plate(12.0, 12.0, n)
    return SurfaceMesh.from_surface(plate.vertices_mm, plate.triangles)


def full_compliance(layer) -> np.ndarray:
    return np.column_stack([layer.deflection(col) for col in np.eye(layer.local_mm_per_n.shape[0])])


@pytest.mark.parametrize("symbol", tuple(LAYER_SYMBOLS))
def test_coarse_smoothing_deflects_a_closed_layer_uniformly_under_uniform_pressure(symbol):
    # On a closed surface (no free edge) the coarse functions sum to one (P 1 = 1) and K 1 = 0, so
    # H_c 1 = P^T Q^T diag(A c_nl) 1 and S 1 = 1: h p / E' at every spring to round-off, as on the
    # springs' own vertices (thickness varying: S 1 = 1 for any h).
    mesh = sphere(3000, 15.0)  # springs sqrt(2 A) about 1 mm across
    cells = np.arange(mesh.area_mm2.shape[0])
    centroid = mesh.vertices_mm[mesh.triangles].mean(axis=1)
    h = 3.0 + 0.5 * centroid[:, 2] / 15.0  # 2.5 .. 3.5 mm: the bulge term's coarse cells about 1.2 h = 3.7 mm
    for nu in (0.42, 0.499):  # below nu 1/4 the Pade's term is short (sqrt(b) = 0.24 at nu 0.1) and stays fine
        layer = layer_compliance(mesh, cells, h, E, nu, symbol=LAYER_SYMBOLS[symbol](nu), smoothing_resolution=1.0)
        coarse = [t.coarse for t in layer.terms if t.coarse is not None]
        assert coarse and all(c.transfer.shape[1] < c.transfer.shape[0] / 4 for c in coarse)  # it is coarse
        w = layer.deflection(2.0 * mesh.area_mm2)
        np.testing.assert_allclose(w, h * 2.0 / confined_modulus_mpa(E, nu), rtol=1e-9)


def test_coarse_pade_compliance_is_symmetric_positive_definite_and_at_least_the_fine_one():
    """A Galerkin space: P H_c^-1 P^T <= H^-1, so the bulge term's (sigma = -1) coarse part removes
    less and C_coarse - C_fine is positive semidefinite; C_coarse is symmetric and, as the fine
    one, at least the independent springs' diag((h/G) e / A) (module docstring). Round-off:
    1e-12 of the largest entry."""
    mesh = plate_mesh(16)  # springs 0.75 mm
    cells = np.arange(mesh.area_mm2.shape[0])
    thickness = 1.5 + 0.2 * np.arange(cells.size) / cells.size
    for nu in (0.42, 0.499):
        fine = full_compliance(layer_compliance(mesh, cells, thickness, E, nu))
        layer = layer_compliance(mesh, cells, thickness, E, nu, smoothing_resolution=1.0)
        assert layer.terms[0].coarse is not None
        coarse = full_compliance(layer)
        scale = np.abs(coarse).max()
        np.testing.assert_allclose(coarse, coarse.T, atol=1e-12 * scale)
        assert np.linalg.eigvalsh(0.5 * (coarse + coarse.T) - fine).min() > -1e-12 * scale
        springs = np.diag(thickness / confined_modulus_mpa(E, nu) / mesh.area_mm2)
        assert np.linalg.eigvalsh(0.5 * (coarse + coarse.T) - springs).min() > -1e-12 * scale


def test_coarse_smoothing_converges_to_the_fine_operator_as_its_cells_shrink(monkeypatch):
    """The deflection under a bump of pressure approaches the fine operator's as the coarse cells
    shrink (4, 2.8, 2 springs across, the guard COARSE_MIN_SPRINGS lifted), and equals it to
    round-off once every vertex is a coarse vertex (cells below the springs' spacing: P = I)."""
    import edem.thin_layer as thin_layer

    monkeypatch.setattr(thin_layer, "COARSE_MIN_SPRINGS", 0.0)
    mesh = plate_mesh(24)  # 0.5 mm squares: springs sqrt(2 A) = 0.5 mm
    cells = np.arange(mesh.area_mm2.shape[0])
    centroid = mesh.vertices_mm[mesh.triangles].mean(axis=1)
    force = np.exp(-np.sum(centroid[:, :2] ** 2, axis=1) / 4.0) * mesh.area_mm2
    fine = layer_compliance(mesh, cells, 2.0, E, 0.49).deflection(force)
    length = np.sqrt(pade_coefficients(0.49)[2]) * 2.0  # the smoothing length sqrt(b) h
    errors = []
    for size in (2.0, 1.4, 1.0, 0.2):  # mm; 0.2 < 0.5 / sqrt(3): at most one vertex per cube
        w = layer_compliance(mesh, cells, 2.0, E, 0.49, smoothing_resolution=length / size).deflection(force)
        errors.append(np.linalg.norm(w - fine) / np.linalg.norm(fine))
    assert errors[0] > errors[1] > errors[2] > 1e3 * errors[3]
    assert errors[3] < 1e-12


def test_a_stacked_pattern_past_46341_fields_is_the_assembled_matrix():
    # Keys row * n + column exceed 2^31 once n > 46341 stacked fields (two terms of ~25k vertices:
    # a two-pole bed on ~0.12 mm springs of the 30 x 40 mm cylinder layer); scipy's int32 indices
    # wrapped there and the build failed. The stacked data must equal diag(H_1, H_2) + Z diag(x) Z^T.
    from edem.sparse_factors import OperatorPattern, StackedPattern

    v = 24_000
    diagonal = OperatorPattern(np.arange(v, dtype=np.int32), np.arange(v + 1, dtype=np.int32))
    m = v
    rows = np.repeat(np.arange(m), 2)
    columns = np.column_stack([np.arange(m), v + (np.arange(m) * 7) % v]).ravel()  # spring j couples j and a far field
    z_t = sp.csr_matrix((np.tile([1.0, -0.5], m), (rows, columns)), shape=(m, 2 * v))
    assert z_t.indices.dtype == np.int32
    stacked = StackedPattern.build([diagonal, diagonal], z_t)
    x = np.linspace(0.5, 2.0, m)
    data = stacked.blocks([np.full(v, 3.0), np.full(v, 4.0)]) + stacked.coupling(z_t) @ x
    expected = sp.block_diag([3.0 * sp.eye(v), 4.0 * sp.eye(v)]) + z_t.T @ sp.diags(x) @ z_t
    assert abs(stacked.pattern.matrix(data) - expected).max() == 0.0  # the same sums, each of the same terms
