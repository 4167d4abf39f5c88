"""Closed forms of the discrete method (verification/closed_forms.py) against hand values, their
own defining relations (force balance, the log law's inverse) and the solver where they are exact."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad

from geometries.errors import InputError
from edem.solver import run
from verification.campaigns import SCENES_DIR, ramp_overrides
from verification.closed_forms import (
    geometry_parameters,
    log_law_edem_error,
    log_law_edem_max_error,
    solve_closed_form,
    write_closed_form_results,
)
from verification.metrics import compare_result_dirs

PLATES = str(SCENES_DIR / "flat-plates.toml")


def e_conf(e: float = 10.35, nu: float = 0.42) -> float:
    return e * (1 - nu) / ((1 + nu) * (1 - 2 * nu))


def test_flat_plates_hand_values_and_dem_reproduces_them():
    """p = F / A = 400 / 400 = 1 MPa; d = F h / (E' A) = 400 * 2 / (E' 400)."""
    scene, sol = solve_closed_form("flat-plates", PLATES)
    assert sol.peak_pressure_mpa[0] == pytest.approx(1.0)
    assert sol.displacement_mm[0, 2] == pytest.approx(2.0 / e_conf())
    assert sol.contact_area_mm2[0] == pytest.approx(400.0)
    step = run(scene, "dem").steps[-1]
    np.testing.assert_allclose(step.pressure_mpa, sol.pressure_mpa[0], rtol=1e-12)
    np.testing.assert_allclose(step.displacement_mm, sol.displacement_mm[0], rtol=1e-12, atol=1e-15)


def test_geometry_parameters_merge_the_generator_defaults_and_overrides():
    params = geometry_parameters(PLATES, {"geometry.gap_mm": 1.25})
    assert params["builtin"] == "flat_plates" and params["gap_mm"] == 1.25 and params["n_per_side"] == 10
    ideal = geometry_parameters(SCENES_DIR / "cylinder-plane.toml")
    assert ideal["radius_mm"] == 20.0 and ideal["plafond_tilt_deg"] == 0.0  # default, and the scene's value


def test_tilted_plane_force_balance_and_the_log_integral():
    """sum_i p_i A_i = F (up to the midpoint rule), and D int dx / (g + x tan a) = D ln(h+/h-) / tan a."""
    scene, sol = solve_closed_form("tilted-plane", str(SCENES_DIR / "tilted-plane.toml"))
    force = float((sol.pressure_mpa[0] * scene.spring_area_mm2).sum())
    assert force == pytest.approx(400.0, rel=1e-4)
    g, slope = 2.0, math.tan(math.radians(3.0))
    integral = 20.0 * quad(lambda x: 1.0 / (g + x * slope), -10.0, 10.0)[0]
    assert sol.displacement_mm[0, 2] == pytest.approx(400.0 / (e_conf() * integral), rel=1e-12)
    np.testing.assert_allclose(sol.spring_length_mm, g + scene.spring_centroid_mm[:, 0] * slope)


def test_cylinder_plane_recovers_the_load_and_the_contact_edge():
    """F = int p cos(phi) dA over |phi| <= phi_c, with h(phi_c) = h_max."""
    scene, sol = solve_closed_form("cylinder-plane", str(SCENES_DIR / "cylinder-plane.toml"))
    r, w, g, h_max = 20.0, 28.0, 1.5, 3.5
    phi_c = math.radians(sol.extra["contact_half_angle_deg"])
    assert (r + g) / math.cos(phi_c) - r == pytest.approx(h_max)
    d = sol.displacement_mm[0, 2]
    force = w * r * quad(lambda f: e_conf() * d * math.cos(f) ** 2 / ((r + g) / math.cos(f) - r), -phi_c, phi_c)[0]
    assert force == pytest.approx(333.0, rel=1e-10)
    assert sol.contact_area_mm2[0] == pytest.approx(2 * phi_c * r * w)
    assert sol.extra["peak_pressure_at_top_mpa"] == pytest.approx(e_conf() * d / g)


def test_log_law_inverts_to_the_integrated_stiffness():
    """F = E' A ln(h0 / (h0 - d)): integrating k(h) = E' A / h from h0 down to h0 - d."""
    scene, sol = solve_closed_form("log-law", str(SCENES_DIR / "log-law-ramp.toml"))
    d = sol.displacement_mm[:, 2]
    np.testing.assert_allclose(e_conf() * 400.0 * np.log(2.0 / (2.0 - d)), sol.force_n[:, 2], rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("n", [3, 10])
def test_edem_after_n_increments_is_the_discrete_log_law(n):
    """EDEM gives h0 (1 - (1 - x/n)^k) after k of n increments: its error against the log law is
    exactly log_law_edem_error, at every time point."""
    overrides = ramp_overrides(n, 10_000.0)
    scene, sol = solve_closed_form("log-law", str(SCENES_DIR / "log-law-ramp.toml"), overrides)
    d_edem = np.array([s.displacement_mm[2] for s in run(scene, "edem").steps])
    x = 10_000.0 / (e_conf() * 400.0)
    for k in range(1, n + 1):
        error = abs(d_edem[k] - sol.displacement_mm[k, 2]) / sol.displacement_mm[k, 2]
        assert error == pytest.approx(log_law_edem_error(x, n, k), rel=1e-9)
    assert log_law_edem_max_error(x, n) >= log_law_edem_error(x, n)


def test_hemisphere_thickness_and_faceting_bound_shrink_with_subdivision():
    bounds = []
    for level in (1, 3):
        scene, sol = solve_closed_form("hemisphere-thickness", "hemisphere-convergence", {"geometry.subdivisions": level})
        assert sol.extra["thickness_mm"] == pytest.approx(0.5)
        lengths = run(scene, "dem").steps[0].spring_length_mm
        assert abs(lengths.mean() - 0.5) <= sol.extra["faceting_bound_mm"]
        bounds.append(sol.extra["faceting_bound_mm"])
    assert bounds[1] < bounds[0] / 10


def test_closed_form_result_directory_compares_to_zero_with_itself(tmp_path):
    scene, sol = solve_closed_form("cylinder-plane", str(SCENES_DIR / "cylinder-plane.toml"))
    out = write_closed_form_results(scene, sol, tmp_path / "cf")
    result = compare_result_dirs(out, out)
    assert all(v == 0.0 for v in result["metrics"].values())
    assert result["per_time"][0]["peak_pressure_b_mpa"] == pytest.approx(sol.peak_pressure_mpa[0])


@pytest.mark.parametrize(
    ("form", "scene", "overrides", "key"),
    [
        ("cylinder-plane", PLATES, {}, "geometry.builtin"),
        ("tilted-plane", PLATES, {"constraints.fixed_dofs": ["tx", "ty"]}, "constraints.fixed_dofs"),
        ("flat-plates", PLATES, {"load.force_n": [1.0, 0.0, 100.0]}, "load.force_n"),
        ("log-law", str(SCENES_DIR / "log-law-ramp.toml"), {"load.force_n": [[0.0, 0.0, float(5 - k)] for k in range(9)]}, "load.force_n"),
        ("flat-plates", PLATES, {"cartilage.law": "gap", "cartilage.thickness_mm": 2.5}, "cartilage.law"),
    ],
)
def test_a_closed_form_refuses_scenes_it_does_not_solve(form, scene, overrides, key):
    with pytest.raises(InputError) as info:
        solve_closed_form(form, scene, overrides)
    assert info.value.key == key
