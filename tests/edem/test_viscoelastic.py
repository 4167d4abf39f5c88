"""Viscoelastic EDEM with the thesis's frozen contact set (docs/method.md#4-viscoelastic-edem-thesis-chapter-6,
thesis chapter 6, ``[viscoelastic] contact_set = "frozen"``) against the 1D creep solution and
invariants; the creeping contact set (the default) is tests/edem/test_viscoelastic_creeping.py's."""

from __future__ import annotations

import numpy as np
import pytest
from support import cylinder_patch, grid_plate, make_scene, plane

from geometries.errors import InputError
from edem.mechanics import confined_modulus_mpa
from edem.scene import Viscoelastic
from edem.solver import run
from edem.viscoelastic import integrator_weights

E, NU = 10.35, 0.42
E_CONF = confined_modulus_mpa(E, NU)
IN_PLANE = ("tx", "ty", "rz")
THICKNESS, AREA = 2.0, 400.0
STIFFNESS = AREA * E_CONF / THICKNESS  # linear gap law on flat plates: K is constant


def creep_scene(force_n: float, dt_s: float, n_steps: int, tau_s: float, integrator: str = "exact", **kw):
    """Flat plates touching at rest, linear gap law, load ramped from 0 to F over the first step."""
    time = dt_s * np.arange(n_steps + 1)
    force = np.zeros((n_steps + 1, 3))
    force[1:, 2] = force_n
    return make_scene(
        grid_plate(20, 20, 4),
        plane(lambda x, y: THICKNESS),
        force,
        time_s=time,
        law="gap",
        thickness_mm=THICKNESS,
        max_spring_length_mm=2 * THICKNESS,
        fixed_dofs=IN_PLANE,
        viscoelastic=Viscoelastic(tau_s, integrator, contact_set="frozen", **kw),
    )


def creep_exact(time_s: np.ndarray, force_n: float, dt_s: float, tau_s: float) -> np.ndarray:
    """Solution of tau du/dt + u = F(t)/K, u(0) = 0, F ramped 0 -> F over [0, dt] then held."""
    u_inf = force_n / STIFFNESS
    u_ramp = u_inf * (1.0 - tau_s / dt_s * -np.expm1(-dt_s / tau_s))
    after = u_inf + (u_ramp - u_inf) * np.exp(-(time_s - dt_s) / tau_s)
    during = u_inf * (time_s / dt_s - tau_s / dt_s * -np.expm1(-time_s / tau_s))
    return np.where(time_s >= dt_s, after, during)


def displacement(result) -> np.ndarray:
    return np.array([s.displacement_mm[2] for s in result.steps])


def test_exact_integrator_matches_1d_creep_solution():
    """Step load (ramped over one step): u(t) = F/K + (u(dt) - F/K) exp(-(t - dt)/tau), to 1e-6 relative."""
    tau, dt, force = 1.4, 0.35, 500.0
    result = run(creep_scene(force, dt, 40, tau), "edem")
    t = np.array([s.time_s for s in result.steps])
    expected = creep_exact(t, force, dt, tau)
    np.testing.assert_allclose(displacement(result), expected, rtol=1e-6, atol=1e-12)
    assert displacement(result)[-1] == pytest.approx(force / STIFFNESS * (1 - np.exp(-(t[-1] - dt) / tau)), rel=2e-3)


def test_rk2_is_second_order():
    """The thesis's RK2 at dt = 0.1 tau: error about 1e-3 of the creep, quartered by halving dt."""
    tau, force = 2.0, 500.0
    errors = []
    for dt in (0.1 * tau, 0.05 * tau):
        n = int(round(5 * tau / dt))
        result = run(creep_scene(force, dt, n, tau, "rk2"), "edem")
        t = np.array([s.time_s for s in result.steps])
        errors.append(np.abs(displacement(result) - creep_exact(t, force, dt, tau)).max() / (force / STIFFNESS))
    assert 1e-4 < errors[0] < 5e-3
    assert errors[0] / errors[1] == pytest.approx(4.0, rel=0.1)


def test_stiff_case_exact_integrator_follows_elastic_rk2_refused():
    """tau = 1e-3 s, dt = 0.1 s: the exact integrator gives the elastic answer; RK2 (dt > 2 tau) is refused."""
    tau, dt, force = 1e-3, 0.1, 500.0
    result = run(creep_scene(force, dt, 5, tau), "edem")
    np.testing.assert_allclose(displacement(result)[2:], force / STIFFNESS, rtol=1e-12)
    with pytest.raises(InputError, match=r"dt / tau = 100"):
        run(creep_scene(force, dt, 5, tau, "rk2"), "edem")


def test_rk2_beyond_its_limit_diverges_loudly_when_forced():
    """allow_unstable runs RK2 at dt = 100 tau with a warning; the blow-up is reported, never NaN."""
    from geometries.errors import SolverError

    scene = creep_scene(500.0, 0.1, 400, 1e-3, "rk2", allow_unstable=True)
    with pytest.raises(SolverError, match="diverged|no spring is a candidate|compressed past|ray window"):
        run(scene, "edem")


def test_vanishing_relaxation_time_recovers_elastic_edem():
    """tau -> 0: phi, psi -> 1 and the viscoelastic run equals the elastic EDEM run."""
    assert integrator_weights(1.0, 1e-12, "exact") == pytest.approx((1.0, 1.0), abs=1e-11)
    load = np.column_stack([np.zeros(8), np.zeros(8), np.linspace(0, 1500, 8)])
    common = dict(fixed_dofs=("tx", "rx", "ry", "rz"), time_s=np.arange(8.0))
    cylinder, tibia = cylinder_patch(20.0, 28.0, 114.0, 40, 8), plane(lambda x, y: 1.5)
    elastic = run(make_scene(cylinder, tibia, load, **common), "edem")
    viscous = run(make_scene(cylinder, tibia, load, viscoelastic=Viscoelastic(1e-9, contact_set="frozen"), **common), "edem")
    np.testing.assert_allclose(displacement(viscous), displacement(elastic), rtol=1e-7, atol=1e-15)


def ramp_scene(tau_s: float, dt_s: float = 0.25):
    """The thesis ramp (docs/method.md#4-viscoelastic-edem-thesis-chapter-6): 200 -> 1800 N in 5 s, hold 10 s, back to 200 N in 5 s."""
    time = np.arange(0.0, 20.0 + dt_s / 2, dt_s)
    magnitude = np.interp(time, [0, 5, 15, 20], [200, 1800, 1800, 200])
    direction = np.array([0.0, 0.0, 1.0])  # a flat plafond cannot hold a tangential load: see the scene
    return make_scene(
        cylinder_patch(20.0, 28.0, 114.0, 40, 8),
        plane(lambda x, y: 1.5),
        magnitude[:, None] * direction,
        time_s=time,
        fixed_dofs=("tx", "rx", "ry", "rz"),
        viscoelastic=Viscoelastic(tau_s, contact_set="frozen"),
    )


def test_ramp_equilibrium_every_step_pressure_follows_load_displacement_lags():
    """Elastic + viscous forces balance the load at every step; the lag of the talus grows with tau."""
    at_ramp_end = []
    for tau in (1.4, 7.0, 14.0):
        scene = ramp_scene(tau)
        result = run(scene, "edem")
        normals, areas = scene.spring_normal, scene.spring_area_mm2
        for step in result.steps:
            elastic = step.pressure_mpa - step.viscous_pressure_mpa
            assert np.all(elastic >= 0.0)
            total = ((elastic + step.viscous_pressure_mpa) * areas)[:, None] * normals
            np.testing.assert_allclose(total.sum(axis=0), step.force_n, rtol=1e-9, atol=1e-9 * step.force_n[2])
        peak = np.array([s.peak_pressure_mpa for s in result.steps])
        t = np.array([s.time_s for s in result.steps])
        assert np.all(np.diff(peak[t <= 5.0]) > 0) and np.all(np.diff(peak[t >= 15.0]) < 0)
        at_ramp_end.append(np.linalg.norm(result.steps[int(np.argmin(np.abs(t - 5.0)))].displacement_mm))
    assert at_ramp_end[0] > at_ramp_end[1] > at_ramp_end[2] > 0


def test_unloading_to_zero_creeps_back_to_the_start_on_the_1d_solution():
    """Plates held under 400 N for 4 tau, the load taken to 0 over one step (read as linear within
    it), then held at 0: every spring creeps back with its dashpot, x' = (F(t) - K x) / (K tau), and
    returns to the start. Exact integrator: the discrete solution is the exact one for loads linear
    within a step, to round-off (1e-9 of the loaded displacement)."""
    time = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0, 12.0])
    force = np.zeros((time.size, 3))
    force[1:5, 2] = 400.0
    scene = make_scene(grid_plate(20, 20, 4), plane(lambda x, y: THICKNESS), force, time_s=time, law="gap", thickness_mm=THICKNESS,
                       max_spring_length_mm=2 * THICKNESS, fixed_dofs=IN_PLANE, viscoelastic=Viscoelastic(1.0, "exact", contact_set="frozen"))
    z = np.array([s.displacement_mm[2] for s in run(scene, "edem").steps])
    exact = [0.0]
    for k in range(1, time.size):  # x' = (F(t) - K x) / (K tau), F linear from F0 to F1 over [t0, t1]: exact step
        dt, f0, f1 = time[k] - time[k - 1], force[k - 1, 2], force[k, 2]
        decay = np.exp(-dt)
        exact.append(exact[-1] * decay + (f0 * (1 - decay) + (f1 - f0) * (1 - (1 - decay) / dt)) / STIFFNESS)
    np.testing.assert_allclose(z, exact, rtol=0, atol=1e-9 * max(exact))
    assert z[-1] < 1e-3 * z[4]  # back at the start (within e^-7 of the loaded displacement)


@pytest.mark.parametrize("coupling", ["none", "thin-layer"])
def test_unloading_a_curved_contact_to_zero_creeps_back_without_flying_off(coupling):
    """A cylinder pressed 333 N into a plane for 4 tau, then unloaded to 0 over one step and held:
    the springs that hold an elastic force creep back with their dashpots, so the body returns
    towards its start: the approach falls at every step once unloaded and no displacement exceeds
    the loaded one. Before: with independent springs the ones the zero-load solve had separated
    left a near-singular increment (the body moved by 1.5e4 mm, exit 0); the coupled layer
    refused its zero-load solve, judging a 1e-5 N residual against the vanishing load instead of
    the stored forces it balances away."""
    time = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0])
    force = np.zeros((time.size, 3))
    force[1:5, 2] = 333.0
    scene = make_scene(cylinder_patch(20.0, 30.0, 60.0, 40, 30), plane(lambda x, y: THICKNESS), force, time_s=time, law="gap",
                       thickness_mm=THICKNESS, max_spring_length_mm=2 * THICKNESS, fixed_dofs=("tx", "rx", "ry", "rz"),
                       viscoelastic=Viscoelastic(1.0, "exact", contact_set="frozen"), coupling=coupling)
    u = np.array([s.displacement_mm for s in run(scene, "edem").steps])
    loaded = float(np.abs(u[4, 2]))
    assert loaded > 0.1  # pressed into the layer (0.22 mm)
    assert np.all(np.diff(u[4:, 2]) < 0)  # creeps back at every step once unloaded
    assert float(np.abs(u).max()) <= loaded * (1 + 1e-9)
