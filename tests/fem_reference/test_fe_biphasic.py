"""The linear biphasic FE (fem_reference.biphasic) against confined compression (Mow et al. 1980).

A column 0.5 x 0.5 x 2 mm (box_slab with one cell across, n cells through the thickness) in a
confining chamber: fixed impermeable bottom, lateral rollers, loaded through a free-draining
platen on top. Cartilage-like material: H_A = 0.7 MPa, nu = 0.05, k = 1e-3 mm^4/(N s), hence a
consolidation time T = h^2 / (H_A k) = 5714 s. Errors are relative to the equilibrium
displacement sigma0 h / H_A (displacement), to sigma0 (pressure) and to the peak stress
(relaxation). One set of compiled forms serves every mesh, time step and material here (they
are dolfinx Constants).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from fem_reference import closed_forms as cf
from fem_reference.biphasic import BiphasicMaterial, scheme_weights

pytestmark = pytest.mark.fe

H, WIDTH = 2.0, 0.5
MATERIAL = BiphasicMaterial.from_aggregate_modulus(0.7, 0.05, 1e-3)
HA, K = MATERIAL.aggregate_modulus_mpa, MATERIAL.permeability_mm4_per_n_s
T = MATERIAL.consolidation_time_s(H)
STRESS = 0.1  # MPa, the creep's step
PLATEN = 0.1  # mm, the relaxation's ramp, reached at RAMP
RAMP = 0.1 * T
U_INF = STRESS * H / HA


def test_biphasic_closed_forms_agree_with_their_image_series():
    """Two derivations of each closed form agree: the Fourier series (closed_forms) and the image
    series of the same diffusion problem (reflections in z = 0 and z = h, summed here with 40
    terms), over 1e-6 <= t / T <= 3. Tolerance 1e-12: the series' truncation tolerance, plus
    rounding of the 40-term image sums (measured 1.3e-13 at most)."""
    from scipy.special import erfc

    s = np.geomspace(1e-6, 3.0, 200)
    r = np.sqrt(s)

    def ierfc(x):
        return np.exp(-x**2) / math.sqrt(math.pi) - x * erfc(x)

    creep = 2 * r * (1 / math.sqrt(math.pi) + 2 * sum((-1) ** m * ierfc(m / r) for m in range(1, 40)))
    zeta = 0.3
    pressure = 1 - sum((-1) ** j * (erfc((2 * j + 1 - zeta) / (2 * r)) + erfc((2 * j + 1 + zeta) / (2 * r)))
                       for j in range(40))

    def ramp(x):
        x = np.maximum(x, 1e-300)
        return 2 * np.sqrt(x) * (1 / math.sqrt(math.pi) + 2 * sum(ierfc(m / np.sqrt(x)) for m in range(1, 40)))

    s0 = 0.1
    relaxation = np.where(s <= s0, ramp(s), ramp(s) - ramp(np.clip(s - s0, 0.0, None))) / s0
    assert np.abs(cf.biphasic_creep_fraction(s) - creep).max() < 1e-12
    assert np.abs(cf.biphasic_creep_pressure_fraction(s, zeta) - pressure).max() < 1e-12
    assert np.abs(cf.biphasic_ramp_relaxation_fraction(s, s0) - relaxation).max() < 1e-12


def test_biphasic_closed_forms_start_undrained_and_end_drained():
    """t = 0+: no displacement, the fluid carries the whole load (p = sigma0 below the platen, 0
    at it), no stress before the ramp; t -> infinity (30 T): the drained elastic values sigma0 h /
    H_A and H_A d0 / h; the relaxation's peak is at the end of the ramp and exceeds equilibrium."""
    u, p = cf.biphasic_confined_creep([0.0, 30 * T], H, HA, K, STRESS)
    assert u[0] == 0.0 and p[0] == STRESS
    assert u[1] == pytest.approx(U_INF, rel=1e-12) and abs(p[1]) < 1e-12
    assert cf.biphasic_creep_pressure_fraction(np.array([0.0, 0.1]), 1.0).tolist() == [0.0, 0.0]
    t = np.linspace(0.0, 30 * T, 30001)
    sigma = cf.biphasic_confined_relaxation(t, H, HA, K, PLATEN, RAMP)
    assert sigma[0] == 0.0
    assert sigma[-1] == pytest.approx(HA * PLATEN / H, rel=1e-12)
    assert t[np.argmax(sigma)] == pytest.approx(RAMP, abs=t[1])
    assert sigma.max() > 3 * HA * PLATEN / H  # 3.57 times at t0 = T / 10


@pytest.mark.parametrize("ratio", [0.5, 1.0, 2.0])
def test_scheme_weights_are_consistent(ratio):
    """sum c_j = 1 (a body at rest stays at rest); BDF2 at a constant step is (4 u1 - u2) / 3
    with dt* = 2 dt / 3; a zero step is the undrained jump (dt* = 0, h = u_{n-1})."""
    flow_dt, c = scheme_weights("bdf2", 0.1 * ratio, 0.1)
    assert sum(c) == pytest.approx(1.0, abs=1e-14)
    flow_dt, c = scheme_weights("bdf2", 0.1, 0.1)
    assert flow_dt == pytest.approx(2 * 0.1 / 3) and c == pytest.approx((4 / 3, -1 / 3))
    assert scheme_weights("backward-euler", 0.1, 0.1) == (0.1, (1.0,))
    assert scheme_weights("bdf2", 0.1, None) == (0.1, (1.0,))
    assert scheme_weights("bdf2", 0.0, 0.1) == (0.0, (1.0,))


pytest.importorskip("dolfinx_solver")

from fe_cases import report  # noqa: E402

from fem_reference import Roller, meshes  # noqa: E402
from geometries.errors import SolverError  # noqa: E402
from fem_reference.biphasic import (  # noqa: E402
    CONFINED_COMPRESSION,
    BiphasicBoundaries,
    BiphasicFE,
    PrescribedDisplacement,
    Traction,
    solve_history,
)


@pytest.fixture(scope="module")
def column(comm):
    """BiphasicFE of the confined column with n cells through the thickness, built once each."""
    built = {}

    def get(n_cells: int) -> BiphasicFE:
        if n_cells not in built:
            mesh = meshes.box_slab(comm, WIDTH, WIDTH, H, (1, 1, n_cells))
            # one cell across: each lateral face must still carry its own roller's tag
            assert np.bincount(mesh.facet_tags.values)[4:6].tolist() == [4 * n_cells, 4 * n_cells]
            built[n_cells] = BiphasicFE(mesh, MATERIAL, CONFINED_COMPRESSION)
        return built[n_cells]

    return get


def _times(steps_per_t: int, end: float) -> np.ndarray:
    return np.linspace(0.0, end * T, int(round(end * steps_per_t)) + 1)


def _creep(fe, times, scheme="bdf2"):
    """(platen displacement into the layer, bottom pressure) at ``times`` under the step STRESS."""
    states = solve_history(fe, times, [Traction((0.0, 0.0, -STRESS))] * len(times), scheme)
    return (np.array([-fe.face_mean_displacement_mm(s, 2)[2] for s in states]),
            np.array([fe.face_mean_pressure_mpa(s, 1) for s in states]), states)


def _relaxation(fe, times, scheme="bdf2"):
    """The platen's compressive stress (its support's reaction) under the ramp-and-hold."""
    loads = [PrescribedDisplacement(2, -PLATEN * min(t / RAMP, 1.0)) for t in times]
    states = solve_history(fe, times, loads, scheme)
    return np.array([-fe.reaction_force_n(s, 2)[2] / WIDTH**2 for s in states]), states


def test_confined_creep_follows_mow_series_at_the_project_level(column):
    """The level the project uses: 8 P2-P1 cells through the thickness, BDF2 at dt = T / 100, to
    1.5 T. At every instant, the platen's displacement within 1 % of sigma0 h / H_A (measured
    0.73 %, at the first steps: the drained boundary layer sqrt(c t) is thinner than a cell) and
    the bottom pressure within 0.5 % of sigma0 (measured 0.35 %); each tolerance about 1.4 times
    the measured error. The load is carried: no reaction on the free-draining platen's face."""
    times = _times(100, 1.5)
    u, p, states = _creep(column(8), times)
    u_exact, p_exact = cf.biphasic_confined_creep(times, H, HA, K, STRESS)
    err_u, err_p = np.abs(u - u_exact).max() / U_INF, np.abs(p - p_exact).max() / STRESS
    report("biphasic confined creep (8 cells, T/100, BDF2)", max_err_u=err_u, max_err_p=err_p,
           u_end=u[-1], u_inf=U_INF)
    assert err_u < 0.01
    assert err_p < 0.005
    bottom = column(8).reaction_force_n(states[-1], 1)[2]
    assert bottom == pytest.approx(STRESS * WIDTH**2, rel=1e-9)  # the bottom carries the load


def test_confined_relaxation_follows_mow_ramp_hold_at_the_project_level(column):
    """Ramp to 0.1 mm over T / 10, hold to 1.5 T (8 cells, BDF2, T / 100). The platen's stress
    within 1 % of its peak from 0.04 T after the start of the ramp and of the hold (measured
    0.78 % there, 1.08 % from 0.03 T; right after each kink the drained boundary layer is thinner
    than a cell, the worst 5.1 % at the first step of the ramp); the bottom's reaction balances
    the platen's (the column's force balance, to 1e-9 of the load: the LU's round-off)."""
    times = _times(100, 1.5)
    sigma, states = _relaxation(column(8), times)
    exact = cf.biphasic_confined_relaxation(times, H, HA, K, PLATEN, RAMP)
    settled = (times >= 0.04 * T) & ((times < RAMP) | (times >= RAMP + 0.04 * T))
    err = np.abs(sigma - exact)[settled].max() / exact.max()
    bottom = np.array([column(8).reaction_force_n(s, 1)[2] / WIDTH**2 for s in states])
    report("biphasic confined relaxation (8 cells, T/100, BDF2)", max_err_settled=err,
           max_err_all=np.abs(sigma - exact).max() / exact.max(), peak=sigma.max(), peak_exact=exact.max())
    assert err < 0.01
    assert np.abs(bottom - sigma).max() < 1e-9 * exact.max()


@pytest.mark.parametrize("scheme, order", [("backward-euler", 1.0), ("bdf2", 2.0)])
def test_observed_order_in_time_is_the_schemes(column, scheme, order):
    """dt = T/10, T/20, T/40, T/80 on 64 cells, errors at t = T/2 against the closed forms of the
    creep's displacement and pressure and of the relaxation's stress. Measured: backward Euler
    0.92-1.01, BDF2 2.04-2.59 (pre-asymptotic at T/10). Asserted: every halving at least the
    scheme's order minus 0.1 (the minimum), the last within 0.3 of it; the space error at 64
    cells (1e-5 of the values) is below 5 % of the smallest error here."""
    errors = []
    for n in (10, 20, 40, 80):
        times = _times(n, 0.5)
        u, p, _ = _creep(column(64), times, scheme)
        sigma, _ = _relaxation(column(64), times, scheme)
        u_exact, p_exact = cf.biphasic_confined_creep(times[-1:], H, HA, K, STRESS)
        sigma_exact = cf.biphasic_confined_relaxation(times[-1:], H, HA, K, PLATEN, RAMP)
        errors.append([u[-1] - u_exact[0], p[-1] - p_exact[0], sigma[-1] - sigma_exact[0]])
    orders = np.log2(np.abs(np.array(errors[:-1]) / np.array(errors[1:])))
    report(f"biphasic time orders ({scheme}; u, p, sigma per halving)", orders=orders.T.ravel())
    assert np.all(orders >= order - 0.1)
    assert np.all(np.abs(orders[-1] - order) < 0.3)


def test_observed_order_in_space_is_two(column):
    """2, 4, 8 cells through the thickness at dt = T / 200 (BDF2), errors at t = T/2: second
    order for the platen's displacement, the bottom pressure and the relaxation's stress (P1
    pressure; the platen's displacement is the integral of (p - sigma) / H_A through the
    thickness). Measured 1.90-2.25 (2.00-2.02 from 8 to 32 cells at T/3200); asserted within 0.3
    of 2; the time error at T / 200 is 5 % (u, p) to 13 % (sigma) of the 8 cells' error, which
    lowers sigma's last order by about 0.1."""
    errors = []
    for n_cells in (2, 4, 8):
        times = _times(200, 0.5)
        u, p, _ = _creep(column(n_cells), times)
        sigma, _ = _relaxation(column(n_cells), times)
        u_exact, p_exact = cf.biphasic_confined_creep(times[-1:], H, HA, K, STRESS)
        sigma_exact = cf.biphasic_confined_relaxation(times[-1:], H, HA, K, PLATEN, RAMP)
        errors.append([u[-1] - u_exact[0], p[-1] - p_exact[0], sigma[-1] - sigma_exact[0]])
    orders = np.log2(np.abs(np.array(errors[:-1]) / np.array(errors[1:])))
    report("biphasic space orders (u, p, sigma per halving)", orders=orders.T.ravel())
    assert np.all(np.abs(orders - 2.0) < 0.3)


def test_long_time_equilibrium_is_the_drained_confined_compression(column):
    """Five backward-Euler steps of 10 T: the transient left is below (1 + 2.47 * 10)^-5 = 1e-7
    of the load, so the platen's displacement is sigma0 h / H_A and the pressure 0 within 1e-6;
    the drained problem is linear in z, so the 4-cell mesh is exact."""
    fe = column(4)
    times = np.arange(6) * 10 * T
    u, p, _ = _creep(fe, times, "backward-euler")
    report("biphasic drained equilibrium", u_end=u[-1], u_inf=U_INF, p_end=p[-1])
    assert u[-1] == pytest.approx(U_INF, rel=1e-6)
    assert abs(p[-1]) < 1e-6 * STRESS


def test_undrained_instant_conserves_volume(column, comm):
    """At t = 0+ of a step load no fluid has moved: the volume change (integral of div u) is 0.
    Confined, that leaves no displacement and p = sigma0 everywhere. Unconfined (frictionless
    platens, drained lateral faces), the body answers as an incompressible solid of shear
    modulus mu: u = -sigma0 h / (3 mu), p = sigma0 / 3, exact in P2-P1 (a uniform strain); long
    after (five BE steps of 10 T, T of the 1 mm half-width here 0.25 of the column's), the
    drained Young's modulus: u = -sigma0 h / E, p = 0. Tolerances 1e-9 of the values: the LU's
    round-off (the fields are exact in the element)."""
    confined, *_ = _creep(column(4), np.array([0.0]))[2]
    fe = column(4)
    assert abs(fe.volume_change_mm3(confined)) < 1e-12 * U_INF * WIDTH**2
    assert abs(fe.face_mean_displacement_mm(confined, 2)[2]) < 1e-12 * U_INF
    assert fe.face_mean_pressure_mpa(confined, 1) == pytest.approx(STRESS, rel=1e-9)

    quarter = meshes.box_slab(comm, 1.0, 1.0, H, (2, 2, 2), confined=False, quarter=True)
    free = BiphasicFE(quarter, MATERIAL, BiphasicBoundaries(
        fixed_tags=(), rollers=(Roller(1, 2), Roller(4, 0), Roller(5, 1)), drained_tags=(3,), loaded_tag=2))
    states = solve_history(free, np.arange(6) * 10 * T, [Traction((0.0, 0.0, -STRESS))] * 6, "backward-euler")
    undrained, drained = states[0], states[-1]
    u0, ue = (free.face_mean_displacement_mm(s, 2)[2] for s in (undrained, drained))
    p0, pe = (free.face_mean_pressure_mpa(s, 2) for s in (undrained, drained))
    report("biphasic unconfined undrained / drained", u0=u0, p0=p0, volume0=free.volume_change_mm3(undrained),
           u_end=ue, p_end=pe)
    assert abs(free.volume_change_mm3(undrained)) < 1e-9 * abs(u0)
    assert u0 == pytest.approx(-STRESS * H / (3 * MATERIAL.shear_modulus_mpa), rel=1e-9)
    assert p0 == pytest.approx(STRESS / 3, rel=1e-9)
    assert ue == pytest.approx(-STRESS * H / MATERIAL.youngs_modulus_mpa, rel=1e-6)
    assert abs(pe) < 1e-6 * STRESS


def test_an_undrained_jump_the_fluid_cannot_allow_is_refused(column):
    """A platen displacement applied in one jump to the confined column would need a volume
    change at t = 0+, which the fluid forbids: the singular system factors into a finite but
    meaningless solution (p ~ 8e15 MPa), so the step checks its residual and refuses, naming the
    fix (ramp it); the same displacement ramped over one step solves."""
    fe = column(4)
    with pytest.raises(SolverError, match="ramp"):
        fe.step(fe.at_rest(0.0), 0.0, PrescribedDisplacement(2, -PLATEN))
    ramped = solve_history(fe, [0.0, RAMP], [PrescribedDisplacement(2, 0.0), PrescribedDisplacement(2, -PLATEN)])
    assert np.all(np.isfinite(ramped[-1].solution))
