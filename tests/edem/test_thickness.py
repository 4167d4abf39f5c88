"""Measured cartilage thickness (edem.thickness): each side's layer to its bone, in series.

Closed forms: two uniform layers between flat plates (d = g0 + p (t_M + t_F) / E' for the gap
law, the threshold law at contact, d = g0 + T (1 - exp(-p / E')) for the gap-log law), a tapered
layer with independent springs (p_i = E' d / t_i, d = F / (E' sum A_i / t_i)). Invariants: a
measured uniform layer is the same bed as that uniform thickness, with the coupled layer too.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from edem.errors import InputError
from edem.mechanics import confined_modulus_mpa
from edem.results import summary
from edem.scene import load_scene
from edem.solver import solve
from geometries.mesh_io import write_surface
from geometries.surface import TriangleSurface
from tests.support import grid_plate, make_scene, plane

E, NU = 10.35, 0.42
E_CONF = confined_modulus_mpa(E, NU)
FORCE_N = 400.0  # on the 20 x 20 mm plate: p = 1 MPa
T_M, T_F = 1.2, 0.8  # the two layers (mm)
PLATE_FIXED = ("tx", "ty", "rx", "ry", "rz")


def _arrays(surface: TriangleSurface) -> tuple[np.ndarray, np.ndarray]:
    return surface.vertices_mm, surface.triangles


def _plates(which: str, gap_mm: float, law: str, **options):
    """Two plates whose articular surfaces are ``gap_mm`` apart; ``which`` says where bones are
    given ("mobile", "fixed", "both"); a side without one is its bone with a uniform layer."""
    mobile_bone = which in ("mobile", "both")
    fixed_bone = which in ("fixed", "both")
    # articular surfaces at z = 0 (M) and z = gap (F); bones T_M below and T_F above them
    mobile = grid_plate(20.0, 20.0, 10, z_mm=0.0 if mobile_bone else -T_M)
    fixed = grid_plate(20.0, 20.0, 10, z_mm=gap_mm if fixed_bone else gap_mm + T_F, facing_up=False)
    kwargs = {}
    if mobile_bone:
        kwargs["mobile_bone"] = _arrays(plane(lambda x, y: -T_M))  # (its normals are turned towards the cartilage)
    else:
        kwargs["mobile_thickness_mm"] = T_M
    if fixed_bone:
        kwargs["fixed_bone"] = _arrays(plane(lambda x, y: gap_mm + T_F))
    else:
        kwargs["fixed_thickness_mm"] = T_F
    return make_scene(mobile, fixed, [0.0, 0.0, FORCE_N], law=law, max_spring_length_mm=4.0, fixed_dofs=PLATE_FIXED, **kwargs, **options)


@pytest.mark.parametrize("which", ["mobile", "fixed", "both"])
@pytest.mark.parametrize("law", ["gap", "gap-log", "threshold"])
def test_two_uniform_layers_in_series_match_the_plate_closed_form(which, law):
    # The articular surfaces start 0.3 mm apart (the gap laws close it first; the threshold law
    # has no gap, so it starts in contact).
    gap = 0.0 if law == "threshold" else 0.3
    step = solve(_plates(which, gap, law), method="dem").steps[0]
    p = FORCE_N / 400.0
    total = T_M + T_F
    expected = gap + (total * (1.0 - math.exp(-p / E_CONF)) if law == "gap-log" else p * total / E_CONF)
    # 1e-9 mm: the plates are exact, the lengths are re-measured in float64 (round-off only)
    assert step.displacement_mm[2] == pytest.approx(expected, abs=1e-9)
    assert step.pressure_mpa.max() == pytest.approx(p, rel=1e-9)
    assert step.contact_area_mm2 == pytest.approx(400.0, rel=1e-12)


def test_tapered_layer_matches_independent_springs_with_local_thickness():
    # M's bone is the plane z = -(1.5 + 0.05 x): t(x) from 1.0 to 2.0 mm; F is rigid (no layer),
    # touching M's articular surface. Independent springs: p_i = E' d / t_i, F = sum A_i p_i.
    mobile = grid_plate(20.0, 20.0, 20)
    bone = plane(lambda x, y: -(1.5 + 0.05 * x))
    fixed = grid_plate(20.0, 20.0, 4, z_mm=0.0, facing_up=False)
    scene = make_scene(mobile, fixed, [0.0, 0.0, FORCE_N], law="gap", max_spring_length_mm=3.0, fixed_dofs=PLATE_FIXED,
                       mobile_bone=_arrays(bone), fixed_thickness_mm=0.0)
    step = solve(scene, method="dem").steps[0]
    t = 1.5 + 0.05 * scene.spring_centroid_mm[:, 0]
    d = FORCE_N / (E_CONF * (scene.spring_area_mm2 / t).sum())
    # round-off: the bone is one exact plane, every measured thickness is t(x_i) to float64
    assert step.displacement_mm[2] == pytest.approx(d, rel=1e-9)
    np.testing.assert_allclose(step.pressure_mpa, E_CONF * d / t, rtol=1e-9)
    # the thin side carries more: twice the pressure where the layer is half as thick
    assert step.pressure_mpa.max() / step.pressure_mpa.min() == pytest.approx(t.max() / t.min(), rel=1e-9)


@pytest.mark.parametrize("law", ["gap", "gap-log"])
def test_measured_uniform_layers_are_the_uniform_coupled_layer(law):
    # The coupled thin layer's operator takes the local thickness: a measured T = t_M + t_F
    # everywhere must give the bed of thickness_mm = T (same surfaces, same numbers).
    measured = _plates("mobile", 0.0, law)
    coupled = replace(measured, cartilage=replace(measured.cartilage, coupling="thin-layer"))
    mobile = grid_plate(20.0, 20.0, 10, z_mm=-T_M)
    fixed = grid_plate(20.0, 20.0, 10, z_mm=T_F, facing_up=False)
    uniform = make_scene(mobile, fixed, [0.0, 0.0, FORCE_N], law=law, max_spring_length_mm=4.0, fixed_dofs=PLATE_FIXED,
                         thickness_mm=T_M + T_F)
    uniform = replace(uniform, cartilage=replace(uniform.cartilage, coupling="thin-layer"))
    a, b = solve(coupled, method="dem").steps[0], solve(uniform, method="dem").steps[0]
    # same equations on the same surfaces: round-off only
    assert a.displacement_mm[2] == pytest.approx(b.displacement_mm[2], rel=1e-9)
    np.testing.assert_allclose(a.pressure_mpa, b.pressure_mpa, rtol=1e-7, atol=1e-12)
