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

from geometries.errors import InputError
from edem.beds import CoupledThinLayer, on_bed
from edem.mechanics import confined_modulus_mpa
from edem.scene import load_scene
from edem.solver import solve
from geometries.mesh_files import write_surface
from geometries.surface import TriangleSurface
from support import grid_plate, make_scene, plane

E, NU = 10.35, 0.42
E_CONF = confined_modulus_mpa(E, NU)
FORCE_N = 400.0  # on the 20 x 20 mm plate: p = 1 MPa
T_M, T_F = 1.2, 0.8  # the two layers (mm)
PLATE_FIXED = ("tx", "ty", "rx", "ry", "rz")


def _arrays(surface: TriangleSurface) -> tuple[np.ndarray, np.ndarray]:
    return surface.vertices_mm, surface.triangles


def _plates(which: str, gap_mm: float, law: str, force_n=(0.0, 0.0, FORCE_N)):
    """Two plates whose articular surfaces are ``gap_mm`` apart; ``which`` says where bones are
    given ("mobile", "fixed", "both"; "neither": none); a side without one is its bone with a uniform layer."""
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
    return make_scene(mobile, fixed, force_n, law=law, max_spring_length_mm=4.0, fixed_dofs=PLATE_FIXED, **kwargs)


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


@pytest.mark.parametrize("law", ["gap", "gap-log"])
def test_edem_load_ramp_through_measured_layers_follows_the_closed_form_at_every_step(law):
    # EDEM re-measures the bone-to-bone lengths at every pose (F's layer at the triangle each ray
    # meets): over a ramp each step must sit where the closed form puts the static answer.
    forces = np.array([100.0, 200.0, 400.0])
    scene = _plates("both", 0.3, law, force_n=np.column_stack([0 * forces, 0 * forces, forces]))
    total = T_M + T_F
    for step, force in zip(solve(scene, method="edem").steps, forces):
        p = force / 400.0
        expected = 0.3 + (total * (1.0 - math.exp(-p / E_CONF)) if law == "gap-log" else p * total / E_CONF)
        # plates: the laws are exact and the poses re-measured in float64 (round-off only)
        assert step.displacement_mm[2] == pytest.approx(expected, abs=1e-9)


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
    # The coupled thin layer's operator takes the local thickness: measured layers t_M and t_F
    # everywhere must give the bed of uniform layers t_M and t_F (the sandwich, one operator per
    # layer), and lumped (thin_layer_stack = "lumped") the bed of thickness_mm = T = t_M + t_F
    # (same surfaces, same numbers).
    measured = _plates("mobile", 0.0, law)
    mobile = grid_plate(20.0, 20.0, 10, z_mm=-T_M)
    fixed = grid_plate(20.0, 20.0, 10, z_mm=T_F, facing_up=False)
    lumped = make_scene(mobile, fixed, [0.0, 0.0, FORCE_N], law=law, max_spring_length_mm=4.0, fixed_dofs=PLATE_FIXED,
                        thickness_mm=T_M + T_F)
    for stack, uniform in (("sandwich", _plates("neither", 0.0, law)), ("lumped", lumped)):
        a, b = (solve(replace(scene, cartilage=on_bed(scene.cartilage, CoupledThinLayer.coupling, thin_layer_stack=stack)), method="dem").steps[0]
                for scene in (measured, uniform))
        # same equations on the same surfaces: round-off only
        assert a.displacement_mm[2] == pytest.approx(b.displacement_mm[2], rel=1e-9)
        np.testing.assert_allclose(a.pressure_mpa, b.pressure_mpa, rtol=1e-7, atol=1e-12)


# --------------------------------------------------------------------------------------------
# scene files


def _plate_scene_file(tmp_path, cartilage: str, geometry: str = 'mobile_bone = "bone.stl"') -> str:
    write_surface(tmp_path / "mobile.stl", grid_plate(20.0, 20.0, 10))
    write_surface(tmp_path / "bone.stl", grid_plate(24.0, 24.0, 4, z_mm=-T_M))
    write_surface(tmp_path / "fixed.stl", grid_plate(20.0, 20.0, 10, z_mm=T_F, facing_up=False))
    path = tmp_path / "plates.toml"
    path.write_text(
        f'[geometry]\nmobile = "mobile.stl"\nfixed = "fixed.stl"\n{geometry}\n\n'
        f"[cartilage]\nyoungs_modulus_mpa = {E}\npoissons_ratio = {NU}\n{cartilage}\n\n"
        f"[load]\nforce_n = [0, 0, {FORCE_N}]\n\n[constraints]\nfixed_dofs = {json.dumps(list(PLATE_FIXED))}\n"
    )
    return str(path)


def test_scene_file_bone_gives_the_series_closed_form_and_the_thickness_distribution(tmp_path):
    scene = load_scene(_plate_scene_file(tmp_path, f'law = "gap"\nmax_spring_length_mm = 4.0\nfixed_thickness_mm = {T_F}'))
    run = solve(scene, method="dem")
    # p = 1 MPa through both layers in series; round-off only (exact plates, ascii STL is lossless)
    assert run.steps[0].displacement_mm[2] == pytest.approx((T_M + T_F) / E_CONF, abs=1e-9)
    report = json.loads(json.dumps(run.summary()))["cartilage_thickness"]
    assert report["mobile"]["source"] == "bone" and report["fixed"]["source"] == "uniform"
    for key in ("min_mm", "median_mm", "max_mm"):
        assert report["mobile"][key] == pytest.approx(T_M, abs=1e-9)
        assert report["fixed"][key] == T_F
    assert report["mobile"]["measured_area_share"] == 1.0 and report["fixed"]["uniform_area_share"] == 1.0


@pytest.mark.parametrize(
    ("cartilage", "geometry", "key"),
    [
        # one combined thickness beside per-side layers: which one is meant is not known
        ('law = "gap"\nmax_spring_length_mm = 4.0\nthickness_mm = 2.0\nfixed_thickness_mm = 0.8', 'mobile_bone = "bone.stl"', "cartilage.thickness_mm"),
        # F has neither a bone nor a uniform layer
        ('law = "gap"\nmax_spring_length_mm = 4.0', 'mobile_bone = "bone.stl"', "cartilage.fixed_thickness_mm"),
        # the window cannot default to twice a thickness that is not one number
        ("law = \"gap\"\nfixed_thickness_mm = 0.8", 'mobile_bone = "bone.stl"', "cartilage.max_spring_length_mm"),
        # the rays stop before the articular surfaces meet (0.8 + 1.2 mm of uniform layers)
        ("law = \"gap\"\nmax_spring_length_mm = 1.5\nmobile_thickness_mm = 1.2\nfixed_thickness_mm = 0.8", "", "cartilage.max_spring_length_mm"),
    ],
)
def test_layer_keys_that_contradict_each_other_are_refused_naming_the_key(tmp_path, cartilage, geometry, key):
    with pytest.raises(InputError) as caught:
        load_scene(_plate_scene_file(tmp_path, cartilage, geometry))
    assert caught.value.key == key and caught.value.file.endswith("plates.toml")


def test_result_maps_carry_each_sides_layer(tmp_path):
    # The pressure maps carry M's layer and fixed.vtp F's, as measured (1.2 mm to the bone plate)
    # and as given (0.8 mm uniform): ParaView shows the thickness the springs used.
    from edem.resultdir import read_result_dir, read_surface_frame
    from edem.results import write_results

    scene = load_scene(_plate_scene_file(tmp_path, f'law = "gap"\nmax_spring_length_mm = 4.0\nfixed_thickness_mm = {T_F}'))
    out = write_results(solve(scene, method="dem"), tmp_path / "out")
    np.testing.assert_allclose(read_result_dir(out).frame(0).cell_data["thickness_mm"], T_M, atol=1e-9)  # float64 re-measure
    np.testing.assert_array_equal(read_surface_frame(out / "fixed.vtp").cell_data["thickness_mm"], T_F)
