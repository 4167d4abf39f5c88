"""The coupled layer's sandwich: two layers, each bonded to its bone, frictionless between them.

Its compliance is the sum of the two layers' (docs/method.md, "Two layers: the sandwich"):
checked on the operator (edem.thin_layer: the sum, symmetry and definiteness, a uniform pressure,
the long-wave term h1^3 + h2^3, the summed exact symbol on a periodic grid, a layer of zero
thickness) and through the contact solve (edem.thin_layer_contact: the squeeze film of two equal
layers against its closed form, KKT on a two-layer cylinder, a side without cartilage).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from support import cylinder_patch, disk_plate, grid_plate, make_scene, periodic_grid, plane

from edem.beds import CoupledThinLayer, on_bed
from edem.layer_symbols import LAYER_SYMBOLS, _definiteness_margin, exact_layer_compliance, pade_coefficients, taylor_coefficients
from edem.mechanics import confined_modulus_mpa, generalised_directions
from edem.raycast import RayCaster
from edem.solver import run
from edem.springs import Placement, spring_geometry
from edem.thin_layer import SurfaceMesh, layer_compliance
from edem.thin_layer_contact import ActiveSystem, CoupledStep, coupled_layer_mesh

E = 10.35


def shear_modulus(nu: float) -> float:
    return E / (2 * (1 + nu))


def dense(layer) -> np.ndarray:
    return np.column_stack([layer.deflection(col) for col in np.eye(layer.local_mm_per_n.shape[0])])


# --------------------------------------------------------------------------- the symbol


def navier_state_matrix(k: float, g: float, nu: float) -> np.ndarray:
    """Plane-strain Navier for u_x = U(z) sin kx, u_z = W(z) cos kx, sigma_xz = T(z) sin kx,
    sigma_zz = N(z) cos kx as (U, W, T, N)' = A (U, W, T, N): Hooke's law gives U' and W', the
    two equilibrium equations T' and N'."""
    lam = 2 * g * nu / (1 - 2 * nu)
    c = lam + 2 * g
    return np.array([[0, k, 1 / g, 0], [-lam * k / c, 0, 0, 1 / c], [k * k * (c - lam * lam / c), 0, 0, k * lam / c], [0, 0, -k, 0]])


def two_layer_stack_compliance(k: float, lower: tuple[float, float, float], upper: tuple[float, float, float]) -> float:
    """d / p of two layers (h, G, nu) stacked on 0 < z < h1 < z < h1 + h2, bonded to rigid bases at
    z = 0 and z = h1 + h2, closing a misfit d cos kx at a shear-free interface carrying p cos kx:
    the 8 x 8 system in the states at both bases (U = W = 0 there), each layer's state carried to
    the interface by its propagator expm(A h)."""
    from scipy.linalg import expm

    (h1, g1, nu1), (h2, g2, nu2) = lower, upper
    p1, p2 = expm(navier_state_matrix(k, g1, nu1) * h1), expm(-navier_state_matrix(k, g2, nu2) * h2)
    a = np.zeros((8, 8))
    a[0, 0] = a[1, 1] = a[2, 4] = a[3, 5] = 1.0  # bonded bases
    a[4, :4], a[5, 4:] = p1[2], p2[2]  # no shear on either face
    a[6, :4], a[6, 4:] = p1[3], -p2[3]  # action and reaction
    a[7, :4], a[7, 4:] = -p1[1], p2[1]  # the faces close the misfit: W2 - W1 = d = 1
    y = np.linalg.solve(a, np.eye(8)[7])
    return -1.0 / (p1[3] @ y[:4])


def test_the_two_layer_stack_solved_directly_is_the_sum_of_the_layers_symbols():
    """The sandwich's symbol (docs/method.md) against the plane-strain stack solved as one problem
    (Navier's equations, not the Airy closed form of edem.layer_symbols): d/p = C(h1) + C(h2) for
    equal, unequal and mixed layers at kh = 0.01-12. Round-off: the propagators grow as e^(k h_i)
    (at most e^9.6 = 1.5e4 here) times 2.2e-16, with a safety factor of 3: 1e-11."""
    stacks = [((1.0, 3.6, 0.3), (1.0, 3.6, 0.3)), ((1.5, 3.6, 0.45), (0.5, 3.6, 0.45)), ((1.0, 3.5, 0.499), (1.0, 3.5, 0.499)),
              ((0.7, 3.0, 0.499), (1.6, 5.0, 0.42)), ((1.2, 2.0, 0.0), (0.8, 4.0, 0.49))]
    for lower, upper in stacks:
        total = lower[0] + upper[0]
        for kh in (0.01, 0.2, 1.0, 3.0, 6.0, 12.0):
            k = kh / total
            summed = sum(h * exact_layer_compliance(k * h, nu) / g for h, g, nu in (lower, upper))
            assert two_layer_stack_compliance(k, lower, upper) == pytest.approx(summed, rel=1e-11)


# --------------------------------------------------------------------------- the operator


@pytest.mark.parametrize("symbol", tuple(LAYER_SYMBOLS))
def test_sandwich_compliance_is_the_sum_of_its_layers_and_symmetric_positive_definite(symbol):
    """On a plate with free edges and two layers of varying thickness: C = C(h1) + C(h2) (each
    layer's terms vanish on the free edge as one layer's do), symmetric, and at least
    diag(margin (h1 + h2) / (G A)), the sum of the layers' floors (``_definiteness_margin``).
    Round-off: 1e-12 of the largest entry (sums of a few hundred terms of one sign)."""
    plate = grid_plate(10.0, 10.0, 8)
    mesh = SurfaceMesh.from_surface(plate.vertices_mm, plate.triangles)
    cells = np.arange(plate.n_triangles)
    h1 = 1.0 + 0.1 * np.arange(cells.size) / cells.size
    h2 = 0.6 - 0.2 * np.arange(cells.size) / cells.size
    for nu in (0.1, 0.42, 0.499):
        model = LAYER_SYMBOLS[symbol](nu)
        sandwich = layer_compliance(mesh, cells, np.stack([h1, h2]), E, nu, symbol=model)
        assert len(sandwich.terms) == 2 * len(model.strengths)
        c = dense(sandwich)
        summed = dense(layer_compliance(mesh, cells, h1, E, nu, symbol=model)) + dense(layer_compliance(mesh, cells, h2, E, nu, symbol=model))
        scale = np.abs(c).max()
        np.testing.assert_allclose(c, summed, rtol=0, atol=1e-12 * scale)
        np.testing.assert_allclose(c, c.T, rtol=0, atol=1e-12 * scale)
        strengths = model.strengths + (0.0,) * (2 - len(model.strengths))
        screenings = model.screenings + (1.0,) * (2 - len(model.screenings))
        margin = _definiteness_margin(np.array([model.local]), np.array([strengths]), np.array([screenings]))[0]
        floor = margin * (h1 + h2) / shear_modulus(nu) / mesh.area_mm2
        scaled = (c - np.diag(floor)) / np.sqrt(np.outer(floor, floor))
        assert margin > 0.0 and np.linalg.eigvalsh(0.5 * (scaled + scaled.T)).min() > -1e-9


@pytest.mark.parametrize("symbol", tuple(LAYER_SYMBOLS))
def test_a_uniform_pressure_deflects_the_sandwich_by_the_summed_thickness(symbol):
    """Periodic grid (no free edge): every spring deflects by (h1 + h2) p / E' to round-off (S 1 = 1
    for each layer), also where one layer has no thickness on part of the surface (its term
    vanishes there: its vertices with no thickness around them carry a zero field)."""
    mesh, centroid = periodic_grid(24, 0.7)
    cells = np.arange(mesh.area_mm2.shape[0])
    x = centroid[:, 0] * 2 * np.pi / (24 * 0.7)
    h1 = 1.2 + 0.3 * np.sin(x) ** 2
    for h2 in (0.8 + 0.4 * np.cos(x) ** 2, np.where(np.cos(x) > 0.3, 0.6, 0.0)):
        for nu in (0.1, 0.42, 0.499):
            w = layer_compliance(mesh, cells, np.stack([h1, h2]), E, nu, symbol=LAYER_SYMBOLS[symbol](nu)).deflection(2.0 * mesh.area_mm2)
            np.testing.assert_allclose(w, (h1 + h2) * 2.0 / confined_modulus_mpa(E, nu), rtol=1e-9)


@pytest.mark.parametrize("symbol", tuple(LAYER_SYMBOLS))
def test_a_layer_of_zero_thickness_leaves_the_one_layer_compliance_bit_for_bit(symbol):
    """A side without cartilage (t = 0, rigid): the stack (h, 0) or (0, h) is the layer h, the
    same arrays and the same deflection to the bit."""
    plate = grid_plate(10.0, 10.0, 8)
    mesh = SurfaceMesh.from_surface(plate.vertices_mm, plate.triangles)
    cells = np.arange(plate.n_triangles)
    h = 1.0 + 0.2 * (cells % 5) / 5
    force = np.linspace(0.0, 1.0, cells.size)
    one = layer_compliance(SurfaceMesh.from_surface(plate.vertices_mm, plate.triangles), cells, h, E, 0.49, symbol=LAYER_SYMBOLS[symbol](0.49))
    for stack in (np.stack([h, 0 * h]), np.stack([0 * h, h])):
        mesh.memo.clear()
        layer = layer_compliance(mesh, cells, stack, E, 0.49, symbol=LAYER_SYMBOLS[symbol](0.49))
        np.testing.assert_array_equal(layer.local_mm_per_n, one.local_mm_per_n)
        assert len(layer.terms) == len(one.terms)
        for a, b in zip(layer.terms, one.terms):
            assert a.sigma == b.sigma
            np.testing.assert_array_equal(a.h.toarray(), b.h.toarray())
            np.testing.assert_array_equal(a.z_t.toarray(), b.z_t.toarray())
        np.testing.assert_array_equal(layer.deflection(force), one.deflection(force))


def test_the_long_wave_term_is_the_sum_of_the_layers_cubes():
    """p = cos(kx) at kT = 0.1 on a periodic grid: w/p - T/E' = (c1/G)(h1^3 + h2^3) k^2, the
    independent layers' thin-layer terms, a third of the lumped layer's (c1/G) T^3 k^2 for
    h1 = 1.5, h2 = 0.5. Within 2 %: the O((kh)^2) = 1 % remainder of the series (c2/c1 (kT)^2)
    and the mesh's O((ks)^2) = 1 % (s = 2 mm at k = 0.05/mm)."""
    n, spacing, h1, h2, nu = 64, 2.0, 1.5, 0.5, 0.45
    mesh, centroid = periodic_grid(n, spacing)
    cells = np.arange(mesh.area_mm2.shape[0])
    k = 2 * np.pi / (n * spacing)
    p = np.cos(centroid[:, 0] * k)
    w = layer_compliance(mesh, cells, np.stack([np.full(cells.size, h1), np.full(cells.size, h2)]), E, nu).deflection(p * mesh.area_mm2)
    ratio = w @ p / (p @ p)
    c0, c1, _ = taylor_coefficients(nu)
    g = shear_modulus(nu)
    term = ratio - c0 * (h1 + h2) / g
    assert term == pytest.approx(c1 / g * (h1**3 + h2**3) * k * k, rel=0.02)
    assert (h1 + h2) ** 3 / (h1**3 + h2**3) > 2.0  # (the lumped layer's term is far outside)


@pytest.mark.parametrize("symbol", tuple(LAYER_SYMBOLS))
@pytest.mark.parametrize("nu", (0.3, 0.49))
def test_the_discrete_sandwich_converges_to_the_summed_symbol(nu, symbol):
    """p = cos(kx) on periodic grids of spacing s and s/2, layers 1.2 and 0.8 mm (kT = 1.05, 3.1,
    6.3): the ratio w/p approaches the sum of the layers' symbols, (h1/G) C(k h1) + (h2/G) C(k h2),
    with an error falling 4x per halving (P1, O((k s)^2); 4 +- 20 % for the O((k s)^4) remainder).
    Where both k h_i <= 1.1 it is the summed exact compliance within the larger of the layers'
    symbol bounds (a sum of two positive terms each within its bound) plus that error."""
    h1, h2, length = 1.2, 0.8, 12.0
    g = shear_modulus(nu)
    model = LAYER_SYMBOLS[symbol](nu)
    for mode in (3, 6, 1):
        k = 2 * np.pi * mode / length
        summed = (h1 * model(k * h1) + h2 * model(k * h2)) / g
        errors = []
        for n in (48, 96):
            mesh, centroid = periodic_grid(n, length / n)
            cells = np.arange(mesh.area_mm2.shape[0])
            p = np.cos(centroid[:, 0] * k)
            w = layer_compliance(mesh, cells, np.stack([np.full(cells.size, h1), np.full(cells.size, h2)]), E, nu, symbol=model)
            w = w.deflection(p * mesh.area_mm2)
            lower = slice(0, n * n)
            ratio = w[lower] @ p[lower] / (p[lower] @ p[lower])
            errors.append(ratio - summed)
        if abs(errors[0]) > 1e-6 * summed:  # (above round-off)
            assert errors[0] / errors[1] == pytest.approx(4.0, rel=0.2)
        if k * max(h1, h2) <= 1.1:
            exact = (h1 * exact_layer_compliance(k * h1, nu) + h2 * exact_layer_compliance(k * h2, nu)) / g
            assert ratio == pytest.approx(exact, rel=model.error_bound(nu, 1.1) + abs(errors[1]) / summed + 1e-9)


def flat_punch_stiffness(compliance, short_wave: float, a: float, n_basis: int = 10, t_tail: float = 5e3, dt: float = 0.1) -> float:
    """Plane-strain stiffness (force per length per approach, N/mm per mm) of a rigid flat punch
    |x| < a on a layer of symbol ``compliance`` (k (1/mm) -> mm/MPa; ~ short_wave / k at short
    waves), both faces going on beyond the punch.

    Galerkin in p = sum_n c_n T_2n(x/a) / sqrt(1 - x^2/a^2) (the edge singularity built in), whose
    Fourier transforms are pi a (-1)^n J_2n(ka): sum_n c_n pi a^2 (-1)^(n+m) int C(k) J_2n J_2m dk
    = pi a [m = 0] for a unit approach, force pi a c_0. The k integral (t = ka) by the midpoint
    rule, past t_tail its mean short_wave (-1)^(n-m) / (pi t_tail) (J_2n J_2m ~ cos(...)/(pi t));
    10 functions, dt 0.1 and t_tail 5e3 give the stiffness within 1e-8 of 14, 0.02 and 4e4.
    """
    from scipy.special import jv

    n = np.arange(n_basis)
    t = np.arange(dt / 2, t_tail, dt)
    j = jv(2 * n[:, None], t[None])
    integral = (j * (compliance(t / a) * dt / a)) @ j.T + short_wave * np.where((n[:, None] - n[None]) % 2 == 0, 1.0, -1.0) / (np.pi * t_tail)
    sign = np.where((n[:, None] + n[None]) % 2 == 0, 1.0, -1.0)
    c = np.linalg.solve(np.pi * a * a * sign * integral, np.pi * a * np.eye(n_basis)[0])
    return np.pi * a * c[0]


@pytest.mark.parametrize("nu, a", [(0.3, 1.0), (0.49, 2.0)])
def test_the_beds_flat_punch_lumping_ratio_follows_the_exact_symbols(nu, a):
    """A rigid flat punch (half-width a, plane strain) on h = 1 mm: two layers of h/2 against one of
    h. The exact ratio of their stiffnesses (the summed exact symbol in the punch's integral
    equation): 0.942 at nu 0.3, a = h (the sandwich softer: two half-spaces at the punch's edges),
    1.547 at nu 0.49, a = 2h. The two-pole bed on a plane-strain strip (springs h/16, the punch's
    springs held at a unit approach by the contact solve's own system) gives the lumping error
    the same sign, and its ratio within 9 %: the two-pole symbol's 4.5 % bound on each
    configuration's compliance (measured 0.8 % and 1.3 %; docs/method.md tabulates nu 0.3-0.499)."""
    g = shear_modulus(nu)
    exact = [flat_punch_stiffness(lambda k: sum(h * exact_layer_compliance(k * h, nu) / g for h in layers), len(layers) * (1 - nu) / g, a)
             for layers in ((0.5, 0.5), (1.0,))]
    ratio = exact[0] / exact[1]
    spacing, length = 1.0 / 16, 2 * a + 24.0  # 12 mm on each side: the layers' response decays within a few h
    mesh, centroid = periodic_grid(int(round(length / spacing)), spacing, n_y=3)
    cells = np.arange(mesh.area_mm2.shape[0])
    directions = np.zeros((cells.size, 6))
    directions[:, 2] = 1.0
    punch = np.abs(centroid[:, 0] - length / 2) < a
    bed = []
    for stack in (np.full((2, cells.size), 0.5), np.full(cells.size, 1.0)):
        layer = layer_compliance(mesh, cells, stack, E, nu, symbol=LAYER_SYMBOLS["two-pole"](nu))
        bed.append(ActiveSystem.build(layer, directions, np.zeros(cells.size), punch).force_per_mm[:, 2].sum())
    assert np.sign(bed[0] / bed[1] - 1.0) == np.sign(ratio - 1.0)
    assert bed[0] / bed[1] == pytest.approx(ratio, rel=0.09)


# --------------------------------------------------------------------------- through the contact solve


def coupled(scene, **keys):
    return replace(scene, cartilage=on_bed(scene.cartilage, CoupledThinLayer.coupling, **keys))


@pytest.mark.parametrize("stack", ("sandwich", "lumped"))
def test_two_equal_layers_squeeze_out_four_times_stiffer_than_the_lumped_layer(stack):
    """A rigid plane on a bonded disk (radius a = 8 h) with a layer h/2 on each side, nu = 0.49999.
    Lumped: one layer h, the Pade squeeze film p = (3 G d / 4 h^3)(a^2 - r^2) + 3 b G d / h
    (test_thin_layer_contact). Sandwich: two equal layers, so each deflects by d/2 and the film is
    that of a layer h/2 under d/2: p = (3 G d / h^3)(a^2 - r^2) + 3 b G d / h, four times the
    curvature. Area-weighted L2 within 3 % (mesh h / 6 = the half-layer / 3, as the one-layer
    test's, and the e = 2e-5 compressibility, (a/l)^2/8 < 0.2 % with l = h_i sqrt(c1/e))."""
    h, a, nu, force = 0.75, 6.0, 0.49999, 200.0
    scene = coupled(make_scene(disk_plate(a, 48), plane(lambda x, y: h), [0, 0, force], fixed_dofs=("tx", "ty", "rx", "ry", "rz"),
                               poissons_ratio=nu, law="gap", mobile_thickness_mm=h / 2, fixed_thickness_mm=h / 2, max_spring_length_mm=2 * h),
                    thin_layer_stack=stack)
    step = run(scene, "dem").steps[0]
    assert np.all(step.in_contact)
    r = np.linalg.norm(scene.spring_centroid_mm[:, :2], axis=1)
    g = shear_modulus(nu)
    d = step.displacement_mm[2]
    b = pade_coefficients(nu)[2]
    curvature = 3 * g * d / h**3 * (1.0 if stack == "sandwich" else 0.25)
    expected = curvature * (a**2 - r**2) + 3 * b * g * d / h
    area = scene.spring_area_mm2
    error = np.sqrt((area * (step.pressure_mpa - expected) ** 2).sum() / (area * expected**2).sum())
    assert error < 0.03
    assert abs((area * step.pressure_mpa).sum() - force) <= 1e-9 * force


def two_layer_cylinder(nu: float, **keys):
    """The cylinder-layer case (R 20 mm, 30 mm long, 333 N) with 1.2 mm on the cylinder and 0.8 mm
    on the plane, gap law, only ty and tz free."""
    cylinder = cylinder_patch(20.0, 30.0, 60.0, 48, 30)
    scene = make_scene(cylinder, plane(lambda x, y: 2.0), [0, 0, 333.0], fixed_dofs=("tx", "rx", "ry", "rz"), poissons_ratio=nu, law="gap",
                       mobile_thickness_mm=1.2, fixed_thickness_mm=0.8, max_spring_length_mm=4.0)
    return coupled(scene, **keys)


@pytest.mark.parametrize("symbol", tuple(LAYER_SYMBOLS))
@pytest.mark.parametrize("nu", (0.3, 0.49))
def test_two_layer_cylinder_satisfies_kkt_and_is_stiffer_than_lumped_at_high_nu(nu, symbol):
    """The sandwich's contact (its terms' fields stacked in one block, two or four): p >= 0,
    balance to round-off, and the recomputed surface w = C f touches the plane in contact and
    stays off it outside (1e-9 of the largest compression: the solve's round-off). At nu 0.49 the
    sandwich's thin-layer term is (h1^3 + h2^3) / T^3 = 0.28 of the lumped layer's: the approach
    under the same load is smaller."""
    scene = two_layer_cylinder(nu, thin_layer_symbol=symbol)
    step = run(scene, "dem").steps[0]
    assert np.all(step.pressure_mpa >= 0.0)
    rows_all = generalised_directions(scene.spring_centroid_mm, scene.spring_normal, scene.reference_point_mm)
    resultant = rows_all.T @ (step.pressure_mpa * scene.spring_area_mm2)
    assert abs(resultant[2] - 333.0) <= 1e-10 * 333.0 and abs(resultant[1]) <= 1e-10 * 333.0
    geometry = spring_geometry(scene.spring_centroid_mm, scene.spring_normal, scene.spring_area_mm2,
                               Placement.identity(scene.reference_point_mm), RayCaster(scene.fixed.vertices_mm, scene.fixed.triangles),
                               scene.fixed_placement(0), scene.cartilage)
    cand = geometry.candidate
    rows = generalised_directions(geometry.centroid_mm[cand], geometry.normal[cand], scene.reference_point_mm)
    model = CoupledStep.build(coupled_layer_mesh(scene), geometry, scene.cartilage, np.zeros(cand.sum()), rows, np.zeros((0, 6)), None)
    assert len(model.layer.terms) == 2 * len(LAYER_SYMBOLS[symbol](nu).strengths)
    forces = np.zeros(model.candidate.shape[0])
    forces[model.candidate] = (step.pressure_mpa * scene.spring_area_mm2)[cand]
    w = model.layer.deflection(forces)[model.candidate]
    compression = model.overlap_mm[model.candidate] + rows @ np.concatenate([step.displacement_mm, step.rotation_rad])
    contact = step.in_contact[cand]
    scale = np.abs(compression).max()
    np.testing.assert_allclose(w[contact], compression[contact], atol=1e-9 * scale)
    assert np.all(w[~contact] >= compression[~contact] - 1e-9 * scale)
    if nu > 0.4:
        lumped = run(two_layer_cylinder(nu, thin_layer_symbol=symbol, thin_layer_stack="lumped"), "dem").steps[0]
        assert step.displacement_mm[2] < 0.9 * lumped.displacement_mm[2]


@pytest.mark.parametrize("law", ("gap", "threshold"))
def test_a_side_without_cartilage_gives_the_lumped_bed_to_the_bit(law):
    """fixed_thickness_mm = 0 (or mobile_thickness_mm = 0): one layer, so the sandwich and the
    lumped bed are the same run, array for array, on both symbols."""
    cylinder = cylinder_patch(20.0, 30.0, 60.0, 24, 15)
    for sides in ((2.0, 0.0), (0.0, 2.0)):
        scene = make_scene(cylinder, plane(lambda x, y: 2.0), [0, 0, 333.0], fixed_dofs=("tx", "rx", "ry", "rz"), poissons_ratio=0.49, law=law,
                           mobile_thickness_mm=sides[0], fixed_thickness_mm=sides[1], max_spring_length_mm=4.0)
        for symbol in LAYER_SYMBOLS:
            a, b = (run(coupled(scene, thin_layer_symbol=symbol, thin_layer_stack=stack), "dem").steps[0] for stack in ("sandwich", "lumped"))
            np.testing.assert_array_equal(a.pressure_mpa, b.pressure_mpa)
            np.testing.assert_array_equal(a.displacement_mm, b.displacement_mm)
