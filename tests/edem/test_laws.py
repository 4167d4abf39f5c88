"""The contact-law registry (edem.laws): element laws are consistent, and a new law is one class."""

from __future__ import annotations

import numpy as np
import pytest

from edem.laws import LAWS, GapLaw, LinearElements, LogElements, StackedElements, stack_elements
from edem.mechanics import confined_modulus_mpa
from edem.solver import run
from fem_reference.models import FE_MODELS
from support import grid_plate, make_scene, plane

APPROACH_MM = np.linspace(-0.6, 0.9, 31)


def element_laws():
    n = APPROACH_MM.size
    rng = np.random.default_rng(7)
    linear = LinearElements(rng.uniform(-5, 5, n), rng.uniform(1, 10, n))
    log = LogElements(rng.uniform(-0.5, 0.5, n), rng.uniform(1, 10, n), np.full(n, 2.0))
    return {"linear": linear, "log": log}


@pytest.mark.parametrize("kind", ["linear", "log"])
def test_energy_derivative_is_the_compressive_force(kind):
    """phi'(delta) = max(s(delta), 0): central differences of the energy (step 1e-6 mm; the
    truncation error is O(h^2 phi''') ~ 1e-9 relative here, so 1e-6 is a safe bound)."""
    law = element_laws()[kind]
    h = 1e-6
    slope = (law.energy(APPROACH_MM + h) - law.energy(APPROACH_MM - h)) / (2 * h)
    force, stiffness = law.force_and_stiffness(APPROACH_MM)
    assert np.allclose(slope, np.maximum(force, 0.0), rtol=1e-6, atol=1e-6)
    df = (law.force_and_stiffness(APPROACH_MM + h)[0] - law.force_and_stiffness(APPROACH_MM - h)[0]) / (2 * h)
    assert np.allclose(df, stiffness, rtol=1e-6)


def test_log_law_starts_as_the_linear_law_and_stops_at_the_thickness():
    """-a ln(1 - d/t) = a d / t + O(d^2): the same stiffness at d = 0; infinite energy at d >= t."""
    law = LogElements(np.zeros(1), np.array([4.0]), np.array([2.0]))
    force, stiffness = law.force_and_stiffness(np.array([1e-7]))
    assert force[0] == pytest.approx(4.0e-7, rel=1e-6) and stiffness[0] == pytest.approx(4.0, rel=1e-6)
    assert law.max_approach_mm()[0] == 2.0 and np.isinf(law.energy(np.array([2.0]))[0])


def test_stacked_elements_equal_their_parts_in_order():
    laws = element_laws()
    both = stack_elements(laws["linear"], laws["log"])
    delta = np.concatenate([APPROACH_MM, APPROACH_MM[::-1]])
    expected = np.concatenate([laws["linear"].force_and_stiffness(APPROACH_MM)[0], laws["log"].force_and_stiffness(APPROACH_MM[::-1])[0]])
    assert np.array_equal(both.force_and_stiffness(delta)[0], expected)
    assert len(both) == 2 * APPROACH_MM.size
    assert stack_elements(laws["log"], LinearElements(np.zeros(0), np.zeros(0))) is laws["log"]
    # linear parts only (springs and ligaments) join into one linear law, bit for bit the same
    ligaments = LinearElements(np.array([5.0, -1.0]), np.array([2.0, 3.0]))
    joined = stack_elements(laws["linear"], ligaments)
    assert isinstance(joined, LinearElements) and len(joined) == APPROACH_MM.size + 2
    delta = np.concatenate([APPROACH_MM, [0.5, 1.0]])
    for got, want in zip(joined.force_and_stiffness(delta), StackedElements((laws["linear"], ligaments)).force_and_stiffness(delta)):
        assert np.array_equal(got, want)
    assert np.array_equal(joined.energy(delta), StackedElements((laws["linear"], ligaments)).energy(delta))


def test_every_law_names_an_fe_twin_that_exists():
    assert {law.fe_twin for law in LAWS.values()} <= set(FE_MODELS)


class DoubleGapLaw(GapLaw):
    """A test law: the linear gap law with twice the spring modulus."""

    name = "gap-double"

    def elements(self, area_mm2, spring_length_mm, confined_modulus_mpa, thickness_mm, stored_normal_force_n):
        return super().elements(area_mm2, spring_length_mm, 2.0 * confined_modulus_mpa, thickness_mm, stored_normal_force_n)


def test_a_new_law_is_one_registered_class(monkeypatch):
    """Registered, the class runs through scene validation, the solver and the result: flat
    plates touching at t = 2 mm under p = 1 MPa compress by p t / (2 E') (linear springs: exact)."""
    monkeypatch.setitem(LAWS, DoubleGapLaw.name, DoubleGapLaw())
    scene = make_scene(grid_plate(20, 20, 4), plane(lambda x, y: 2.0, size_mm=20.0), [0, 0, 400.0], law="gap-double",
                       thickness_mm=2.0, max_spring_length_mm=4.0, fixed_dofs=("tx", "ty", "rx", "ry", "rz"))
    step = run(scene, "dem").steps[0]
    assert step.displacement_mm[2] == pytest.approx(1.0 * 2.0 / (2.0 * confined_modulus_mpa(10.35, 0.42)), rel=1e-12)
    assert step.peak_pressure_mpa == pytest.approx(1.0, rel=1e-12)
