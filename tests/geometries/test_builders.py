"""Geometry builders, FE solids and the render (docs/method.md#6-the-fe-reference-and-its-discrete-twins, docs/method.md#8-built-in-geometries; thesis 4.2.2 and 4.3.3)."""

from __future__ import annotations

import math
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from geometries.errors import InputError
from geometries import builders as B
from geometries import fe_solids as F
from geometries.surface import TriangleSurface

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def ideal():
    return B.ideal_ankle(cartilage=False)  # the thesis's geometry: the cylinder under a plane


@pytest.fixture(scope="module")
def ideal_flat():
    return B.ideal_ankle(cartilage=False, plafond_tilt_deg=0.0)


def _plane_ray_lengths(mobile, fixed, tri_index):
    """Exact ray/plane intersection from every mobile centroid along its normal (numpy)."""
    c = mobile.centroids_mm
    n = mobile.unit_normals
    p0 = fixed.vertices_mm[fixed.triangles[tri_index, 0]]
    nf = fixed.unit_normals[tri_index]
    denom = n @ nf
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((p0 - c) @ nf) / denom
    t = np.where((denom < 0) & (t > 0), t, np.inf)
    return t


def _candidate_fraction(built, h_max):
    t = _plane_ray_lengths(built.mobile, built.fixed, 0)  # triangle 0 = plafond
    area = built.mobile.areas_mm2
    return float(area[t <= h_max].sum() / area.sum())


# --------------------------------------------------------------------------------------------
# ideal ankle
# --------------------------------------------------------------------------------------------


def test_cylinder_patch_area_converges_second_order_to_R_arc_width():
    exact = 20.0 * math.radians(114.0) * 28.0
    assert exact == pytest.approx(1115.0, rel=2e-3)  # thesis: 11.15 cm^2
    errors = []
    for size in (2.0, 1.0, 0.5):
        area = B.ideal_ankle(cartilage=False, mesh_size_mm=size).mobile.areas_mm2.sum()
        errors.append((exact - area) / exact)
    assert all(0 < e < 1e-3 for e in errors)  # inscribed facets: always a little smaller
    assert errors[0] > errors[1] > errors[2]
    # faceting error is second order in the mesh size: halving the size divides it by ~4
    for coarse, fine in zip(errors, errors[1:]):
        assert math.log2(coarse / fine) > 1.7


def test_ideal_ankle_default_triangle_count_near_thesis_2974(ideal):
    assert 2500 <= ideal.mobile.n_triangles <= 3500
    assert ideal.fixed.n_triangles == 4  # thesis: 4 triangles for the two planes


def test_ideal_ankle_vertices_on_cylinder_and_normals_outward(ideal):
    v = ideal.mobile.vertices_mm
    r = np.hypot(v[:, 1], v[:, 2] + 20.0)
    np.testing.assert_allclose(r, 20.0, rtol=1e-12)
    assert v[:, 2].max() == pytest.approx(0.0, abs=1e-9)  # dome top at z = 0
    radial = ideal.mobile.centroids_mm - np.array([0.0, 0.0, -20.0])
    radial[:, 0] = 0.0
    assert np.all(np.einsum("ij,ij->i", ideal.mobile.unit_normals, radial) > 0)
    nf = ideal.fixed.unit_normals
    assert nf[0, 2] < -0.99 and nf[1, 2] < -0.99  # plafond faces down, towards the talus
    assert nf[2, 0] > 0.99 and nf[3, 0] > 0.99  # malleolus faces laterally, towards the talus
    np.testing.assert_allclose(ideal.ankle_axis_point_mm, [0.0, 0.0, -20.0])
    np.testing.assert_allclose(ideal.ankle_axis_direction, [1.0, 0.0, 0.0])


def test_ideal_candidate_fraction_matches_closed_form_and_thesis_42_percent(ideal_flat, ideal):
    closed = B.ideal_candidate_fraction(20.0, 1.5, 3.5, 114.0)
    theta = math.acos(21.5 / 23.5)
    assert closed == pytest.approx(2 * theta / math.radians(114.0), rel=1e-12)
    measured = _candidate_fraction(ideal_flat, 3.5)
    assert measured == pytest.approx(closed, abs=0.01)
    assert measured == pytest.approx(0.42, abs=0.01)
    # the default tilt keeps the fraction near 42 % (closed form averaged over x)
    closed_tilt = B.ideal_candidate_fraction(20.0, 1.5, 3.5, 114.0, 28.0, 2.0)
    assert _candidate_fraction(ideal, 3.5) == pytest.approx(closed_tilt, abs=0.01)
    assert closed_tilt == pytest.approx(0.42, abs=0.01)


def test_ideal_tilt_makes_lateral_side_closer(ideal):
    t = _plane_ray_lengths(ideal.mobile, ideal.fixed, 0)
    c = ideal.mobile.centroids_mm
    top = np.abs(c[:, 1]) < 2.0
    lateral, medial = top & (c[:, 0] > 10), top & (c[:, 0] < -10)
    assert t[lateral].mean() < t[medial].mean() - 0.5


def test_ideal_plafond_covers_every_ray_and_malleolus_is_never_hit(ideal):
    t = _plane_ray_lengths(ideal.mobile, ideal.fixed, 0)
    c, n = ideal.mobile.centroids_mm, ideal.mobile.unit_normals
    hit = c + t[:, None] * n
    # every ray meets the plafond plane inside the plafond's triangles (its x-y extent)
    fv = ideal.fixed.vertices_mm[:4]
    assert np.all(np.isfinite(t))
    assert np.all(hit[:, 0] > fv[:, 0].min()) and np.all(hit[:, 0] < fv[:, 0].max())
    assert np.all(np.abs(hit[:, 1]) < np.abs(fv[:, 1]).max())
    # the malleolus plane (either side): every ray meets the plafond first, or never meets it
    nm = ideal.fixed.unit_normals[2]
    p_m = ideal.fixed.vertices_mm[ideal.fixed.triangles[2, 0]]
    with np.errstate(divide="ignore"):
        t_m = ((p_m - c) @ nm) / (n @ nm)
    t_m = np.where(t_m > 0, t_m, np.inf)
    assert np.all(t < t_m)
    # the rays are radial up to faceting (|n_x| < 0.02) and the talus lies lateral of the wall
    assert np.abs(n[:, 0]).max() < 0.02
    assert ideal.mobile.vertices_mm[:, 0].min() > ideal.fixed.vertices_mm[4:, 0].max()


def test_ideal_ankle_is_deterministic():
    for cartilage in (False, True):
        a, b = B.ideal_ankle(cartilage=cartilage, mesh_size_mm=1.5), B.ideal_ankle(cartilage=cartilage, mesh_size_mm=1.5)
        assert np.array_equal(a.mobile.vertices_mm, b.mobile.vertices_mm)
        assert np.array_equal(a.mobile.triangles, b.mobile.triangles)
        assert np.array_equal(a.fixed.vertices_mm, b.fixed.vertices_mm)
        for x, y in ((a.mobile_bone, b.mobile_bone), (a.fixed_bone, b.fixed_bone)):
            assert (x is None and y is None) or (np.array_equal(x.vertices_mm, y.vertices_mm) and np.array_equal(x.triangles, y.triangles))


def test_ligaments_four_named_on_talus_sides_and_tibia_fibula(ideal):
    names = [lig.name for lig in ideal.ligaments]
    assert names == ["ATiTL", "PTiTL", "ATFL", "PTFL"]
    hw = 14.0
    for lig in ideal.ligaments:
        m, f = lig.mobile_point_mm, lig.fixed_point_mm
        length = np.linalg.norm(f - m)
        assert 5.0 < length < 30.0
        assert m[2] < -5.0  # below the articular dome, on the talus body
        if lig.name.endswith("TiTL"):  # tibiotalar: medial side, malleolus medial of the talus
            assert m[0] == pytest.approx(-hw) and f[0] < -hw
        else:  # talofibular: lateral side, fibula lateral of the talus
            assert m[0] > 0 and f[0] > hw
        assert (m[1] > 0) == lig.name.startswith("A")  # anterior vs posterior


# --------------------------------------------------------------------------------------------
# hemispheres, plates
# --------------------------------------------------------------------------------------------


def test_icosphere_hemisphere_area_tends_to_2_pi_R2():
    errors = []
    for n in range(1, 6):
        g = B.hemispheres(subdivisions=n, reference_subdivisions=n, radius_mm=1.0,
                          target_radius_mm=1.5)
        assert g.mobile.n_triangles == 20 * 4**n // 2
        errors.append(1.0 - g.mobile.areas_mm2.sum() / (2 * math.pi))
        assert g.fixed.areas_mm2.sum() / (2 * math.pi * 1.5**2) == pytest.approx(1 - errors[-1])
    assert all(e > 0 for e in errors)
    assert all(a / b > 3.5 for a, b in zip(errors, errors[1:]))
    assert errors[-1] < 5e-4


def test_hemispheres_orientation_vertices_on_spheres_and_exact_length():
    g = B.hemispheres()
    assert g.mobile.n_triangles == 20 * 4**6 // 2
    np.testing.assert_allclose(np.linalg.norm(g.mobile.vertices_mm, axis=1), 1.0, rtol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(g.fixed.vertices_mm, axis=1), 1.5, rtol=1e-12)
    cm, cf = g.mobile.centroids_mm, g.fixed.centroids_mm
    assert np.all(np.einsum("ij,ij->i", g.mobile.unit_normals, cm) > 0)  # outward
    assert np.all(np.einsum("ij,ij->i", g.fixed.unit_normals, cf) < 0)  # inward, to the mobile
    assert np.all(cm[:, 2] > 0) and np.all(cf[:, 2] > 0)
    assert g.parameters["target_radius_mm"] - g.parameters["radius_mm"] == 0.5


def test_flat_and_tilted_plates_structured():
    g = B.flat_plates(width_mm=10.0, depth_mm=6.0, gap_mm=1.0, n_per_side=5)
    assert g.mobile.n_triangles == 50
    assert g.mobile.areas_mm2.sum() == pytest.approx(60.0)
    assert np.all(g.mobile.unit_normals[:, 2] == 1.0)
    assert np.all(g.fixed.unit_normals[:, 2] == -1.0)
    np.testing.assert_allclose(_plane_ray_lengths(g.mobile, g.fixed, 0), 1.0, rtol=1e-14)
    t = B.tilted_plane(width_mm=10.0, depth_mm=6.0, gap_mm=1.0, tilt_deg=5.0, n_per_side=5)
    h = _plane_ray_lengths(t.mobile, t.fixed, 0)
    x = t.mobile.centroids_mm[:, 0]
    np.testing.assert_allclose(h, 1.0 + x * math.tan(math.radians(5.0)), rtol=1e-12)
    with pytest.raises(InputError, match="tilt"):
        B.tilted_plane(width_mm=10.0, gap_mm=0.1, tilt_deg=5.0)


# --------------------------------------------------------------------------------------------
# subject-like ankle
# --------------------------------------------------------------------------------------------


def test_subject_default_counts_and_orientation():
    g = B.subject_ankle()
    assert 2500 <= g.mobile.n_triangles <= 3500
    radial = g.mobile.centroids_mm - np.array([0.0, 0.0, -20.0])
    radial[:, 0] = 0.0
    assert np.all(np.einsum("ij,ij->i", g.mobile.unit_normals, radial) > 0)
    nf = g.fixed.unit_normals
    malleolus = nf[:, 0] > 0.99  # the malleolus faces laterally, towards the talus
    assert 0 < malleolus.sum() < len(nf) // 2
    assert np.all(nf[~malleolus, 2] < 0)  # the plafond faces down, towards the talus
    # the malleolus wall is one plane (tilted with the tibia), medial of the talus
    mv = g.fixed.vertices_mm[np.unique(g.fixed.triangles[malleolus])]
    assert np.ptp(mv @ nf[malleolus][0]) < 1e-9
    assert g.mobile.vertices_mm[:, 0].min() > g.fixed.vertices_mm[:, 0].min() + 1.0
    assert len(g.ligaments) == 4


def test_subject_seeded_determinism_and_ranges():
    a = B.subject_ankle(seed=7, mesh_size_mm=2.0)
    b = B.subject_ankle(seed=7, mesh_size_mm=2.0)
    c = B.subject_ankle(seed=8, mesh_size_mm=2.0)
    assert np.array_equal(a.mobile.vertices_mm, b.mobile.vertices_mm)
    assert np.array_equal(a.mobile.triangles, b.mobile.triangles)
    assert np.array_equal(a.fixed.vertices_mm, b.fixed.vertices_mm)
    assert np.array_equal(a.fixed.triangles, b.fixed.triangles)
    assert a.parameters == b.parameters
    drawn = [name for name in B.SUBJECT_RANGES if name not in B.SUBJECT_THESIS_ONLY]  # cartilage = true, the default
    for name in drawn:
        assert a.parameters[name] != c.parameters[name], name
    assert not set(B.SUBJECT_THESIS_ONLY) & set(a.parameters)
    for seed in range(12):
        p = B.subject_ankle(seed=seed, mesh_size_mm=4.0).parameters
        for name in drawn:
            lo, hi = B.SUBJECT_RANGES[name]
            assert lo <= p[name] <= hi, (seed, name, p[name])
        hw, half_s = p["talar_width_mm"] / 2.0, p["plafond_length_mm"] / 2.0
        for ((xlo, xhi), (slo, shi)), (x, s) in zip(B.SUBJECT_DEPRESSION_RANGES,
                                                    p["depression_positions"]):
            assert xlo * hw <= x <= xhi * hw and slo * half_s <= s <= shi * half_s


def test_subject_explicit_parameter_overrides_only_its_draw():
    a = B.subject_ankle(seed=3, mesh_size_mm=4.0).parameters
    b = B.subject_ankle(seed=3, mesh_size_mm=4.0, talar_radius_mm=22.0).parameters
    assert b["talar_radius_mm"] == 22.0
    for name in a:
        if name != "talar_radius_mm":
            assert a[name] == b[name]
    # the other mode draws the same subject: its shared parameters are the same draws
    thesis = B.subject_ankle(seed=3, mesh_size_mm=4.0, cartilage=False).parameters
    assert {k: v for k, v in thesis.items() if k in a and k != "cartilage"} == {k: v for k, v in a.items() if k in thesis and k != "cartilage"}
    assert set(a) ^ set(thesis) == {"plafond_gap_mm", "talar_cartilage_mm", "tibial_cartilage_mm", "cartilage_taper_mm"}


# --------------------------------------------------------------------------------------------
# ankles with cartilage (the builders' default)
# --------------------------------------------------------------------------------------------


def _corner_thickness(articular, bone, triangles=slice(None)):
    """Distance from each corner of the articular triangles to the same corner of their bone (mm,
    (m, 3)): the layer's offset (articular surface and bone share their triangles)."""
    return np.linalg.norm(articular.vertices_mm[articular.triangles[triangles]] - bone.vertices_mm[bone.triangles[triangles]], axis=2)


def _boundary(triangles):
    """Vertices on the boundary of a triangle set (edges used once)."""
    edges = np.sort(np.vstack([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1)
    unique, count = np.unique(edges, axis=0, return_counts=True)
    return np.unique(unique[count == 1])


def _plafond(built):
    """The plafond's triangles (the malleolus wall's face laterally, within the 0-4 deg tilt)."""
    return built.fixed.unit_normals[:, 0] < 0.99


def test_ideal_layers_are_their_closed_form_tapers_of_the_centre_thickness():
    """Every corner of the ideal ankle's layers is offset by t0 * taper(ML distance) * taper(AP
    distance) (sin^2 over 3 mm) at its bone's parameters, read back from the bone vertex: the
    talar bone on the cylinder R (u = R psi), the tibial bone on the cylinder R_F + t_F whose axis
    the lift placed (s = R_F angle, R_F = (R + t_T)(1 + incongruity)). So the centre value is the
    parameter, the margin 0 and the taper 3 mm wide, to round-off (1e-9 mm)."""
    from geometries.builders.articular import layer_thickness_mm

    g = B.ideal_ankle()
    p = g.parameters
    R, W, arc, w = 20.0, 28.0, math.radians(114.0), p["cartilage_taper_mm"]
    t_talus, t_tibia = p["talar_cartilage_mm"], p["tibial_cartilage_mm"]
    assert (t_talus, t_tibia, w) == (1.3, 1.4, 3.0)
    # talus: the bone on its cylinder, the offset the closed form at its (x, u)
    b = g.mobile_bone.vertices_mm
    np.testing.assert_allclose(np.hypot(b[:, 1], b[:, 2] + R), R, atol=1e-9)
    expected = layer_thickness_mm(t_talus, w, W / 2 - np.abs(b[:, 0]), R * arc / 2 - R * np.abs(np.arctan2(b[:, 1], b[:, 2] + R)))
    offset = np.linalg.norm(g.mobile.vertices_mm - b, axis=1)
    np.testing.assert_allclose(offset, expected, atol=1e-9)
    assert offset.max() == pytest.approx(t_talus, abs=1e-12) and offset.min() == 0.0
    # tibia (the plafond): the bone on the cylinder R_F + t_F about an axis along x at z_c (from any vertex)
    radius_f = (R + t_talus) * (1 + p["incongruity"])
    plafond = _plafond(g)
    d = _corner_thickness(g.fixed, g.fixed_bone, plafond)
    bone = g.fixed_bone.vertices_mm[g.fixed_bone.triangles[plafond]].reshape(-1, 3)
    axis_z = bone[:, 2] - np.sqrt((radius_f + t_tibia) ** 2 - bone[:, 1] ** 2)
    assert np.ptp(axis_z) < 1e-9
    s = radius_f * np.arctan2(bone[:, 1], bone[:, 2] - axis_z[0])
    edge = W / 2 + p["malleolus_gap_mm"]
    expected = layer_thickness_mm(t_tibia, w, edge - np.abs(bone[:, 0]), p["plafond_length_mm"] / 2 - np.abs(s))
    np.testing.assert_allclose(d.ravel(), expected, atol=1e-9)
    assert d.max() == pytest.approx(t_tibia, abs=1e-12)
    # the malleolus wall carries the uniform tibial layer
    np.testing.assert_allclose(_corner_thickness(g.fixed, g.fixed_bone, ~plafond), t_tibia, rtol=1e-12)


def test_subject_layers_are_their_centre_thickness_inside_and_zero_on_the_margin():
    """The subject-like ankle's layers (seeded): at most and somewhere exactly their centre
    thickness, 0 on every boundary vertex (the articular margin), and every triangle keeps some
    (its bare corner triangles split); each parameter drawn within its range."""
    g = B.subject_ankle(seed=11, mesh_size_mm=1.2)
    p = g.parameters
    for name in ("talar_cartilage_mm", "tibial_cartilage_mm"):
        lo, hi = B.SUBJECT_RANGES[name]
        assert lo <= p[name] <= hi
    plafond = _plafond(g)
    for art, bone, t0, tris in ((g.mobile, g.mobile_bone, p["talar_cartilage_mm"], slice(None)),
                                (g.fixed, g.fixed_bone, p["tibial_cartilage_mm"], plafond)):
        d = _corner_thickness(art, bone, tris)
        assert d.max() == pytest.approx(t0, abs=1e-12) and np.all(d <= t0 * (1 + 1e-12))
        margin = np.isin(art.triangles[tris], _boundary(art.triangles[tris]))
        assert margin.any() and np.all(d[margin] < 1e-12)
        assert np.all(d.max(axis=1) > 0.0)  # no triangle lies on its bone


def test_ankle_with_cartilage_keeps_the_axis_and_moves_only_the_tibial_ligament_points():
    """The ankle axis and the talar ligament points are the thesis geometry's; the tibial and
    fibular points move with the tibia by one vertical lift (its placement; both untilted)."""
    for build, untilted in ((B.ideal_ankle, {"plafond_tilt_deg": 0.0}), (B.subject_ankle, {"tilt_deg": 0.0})):
        thesis, cartilage = build(cartilage=False, mesh_size_mm=2.0, **untilted), build(mesh_size_mm=2.0, **untilted)
        np.testing.assert_array_equal(cartilage.ankle_axis_point_mm, thesis.ankle_axis_point_mm)
        np.testing.assert_array_equal(cartilage.ankle_axis_direction, thesis.ankle_axis_direction)
        assert [lig.name for lig in cartilage.ligaments] == [lig.name for lig in thesis.ligaments]
        for a, b in zip(thesis.ligaments, cartilage.ligaments):
            np.testing.assert_array_equal(a.mobile_point_mm, b.mobile_point_mm)
        shift = np.array([b.fixed_point_mm - a.fixed_point_mm for a, b in zip(thesis.ligaments, cartilage.ligaments)])
        np.testing.assert_allclose(shift[:, :2], 0.0, atol=1e-12)
        assert np.ptp(shift[:, 2]) < 1e-12


# --------------------------------------------------------------------------------------------
# registry and errors
# --------------------------------------------------------------------------------------------


def test_build_geometry_resolves_defaults():
    g = B.build_geometry("flat_plates", {"gap_mm": 3})
    assert g.parameters == {"width_mm": 20.0, "depth_mm": 20.0, "gap_mm": 3.0, "n_per_side": 20}
    assert set(B.builder_names()) == {"ideal_ankle", "hemispheres", "subject_ankle",
                                      "flat_plates", "tilted_plane"}


def test_resolved_parameters_rebuild_the_same_geometry():
    for name, params in (("ideal_ankle", {"mesh_size_mm": 2.0}), ("hemispheres", {}),
                         ("tilted_plane", {}), ("subject_ankle", {"seed": 5, "mesh_size_mm": 3.0})):
        a = B.build_geometry(name, params)
        b = B.build_geometry(name, a.parameters)
        assert b.parameters == a.parameters
        assert np.array_equal(a.mobile.vertices_mm, b.mobile.vertices_mm)
        assert np.array_equal(a.fixed.triangles, b.fixed.triangles)
        assert a.description


def test_a_repeated_build_is_a_private_copy_of_the_kept_one_with_its_warnings_again(monkeypatch):
    """A campaign worker builds one geometry for many cases: the second build must not mesh
    again, must equal a fresh build, must not share arrays with the first (a caller may change
    them) and must report the builder's warnings again (the scene records them per run)."""
    calls = []

    def counted(**params):
        calls.append(params)
        warnings.warn("plates drawn for the test", UserWarning)
        return B.flat_plates(**params)

    monkeypatch.setitem(B._BUILDERS, "counted_plates", (counted, B.PLATE_PARAMS))
    B.clear_geometry_cache()
    with pytest.warns(UserWarning, match="plates drawn"):
        first = B.build_geometry("counted_plates", {"gap_mm": 2.0})
    first.mobile.vertices_mm[:] = 0.0  # the caller's copy: the kept geometry must not change
    with pytest.warns(UserWarning, match="plates drawn"):
        second = B.build_geometry("counted_plates", {"gap_mm": 2.0})
    assert len(calls) == 1
    fresh = B.flat_plates(gap_mm=2.0)
    assert np.array_equal(second.mobile.vertices_mm, fresh.mobile.vertices_mm)
    assert np.array_equal(second.fixed.triangles, fresh.fixed.triangles)
    assert second.parameters == fresh.parameters
    # other values (2 is not 2.0 for the key) and the eviction of the oldest are real builds
    for gap in (2, 3.0, 4.0, 5.0, 6.0):
        with pytest.warns(UserWarning):
            B.build_geometry("counted_plates", {"gap_mm": gap})
    assert len(calls) == 6 and len(B._BUILT) == B.BUILT_CACHE_SIZE
    with pytest.warns(UserWarning):
        B.build_geometry("counted_plates", {"gap_mm": 2.0})  # evicted by the four newer ones
    assert len(calls) == 7
    # a builder replaced under the same name (a test's stand-in, say) is never served the old one's geometry
    monkeypatch.setitem(B._BUILDERS, "counted_plates", (lambda **params: B.tilted_plane(**params), B.PLATE_PARAMS))
    assert B.build_geometry("counted_plates", {"gap_mm": 2.0}).parameters == B.tilted_plane(gap_mm=2.0).parameters
    B.clear_geometry_cache()


def test_build_geometry_errors_unknown_builder_parameter_type_range():
    with pytest.raises(InputError) as e:
        B.build_geometry("cylinder", {}, file="scene.toml")
    assert e.value.file == "scene.toml" and "ideal_ankle" in str(e.value)
    with pytest.raises(InputError) as e:
        B.build_geometry("ideal_ankle", {"radius": 20.0}, file="scene.toml")
    assert e.value.key == "geometry.radius" and "radius_mm" in str(e.value)
    assert e.value.file == "scene.toml"
    with pytest.raises(InputError) as e:
        B.build_geometry("ideal_ankle", {"radius_mm": "20"}, file="scene.toml")
    assert e.value.key == "geometry.radius_mm" and "wrong type" in str(e.value)
    with pytest.raises(InputError) as e:
        B.build_geometry("hemispheres", {"subdivisions": 2.0})
    assert e.value.key == "geometry.subdivisions"
    with pytest.raises(InputError) as e:
        B.build_geometry("ideal_ankle", {"malleolus": 1})
    assert e.value.key == "geometry.malleolus"
    with pytest.raises(InputError) as e:
        B.build_geometry("ideal_ankle", {"radius_mm": -1.0}, file="scene.toml")
    assert e.value.key == "geometry.radius_mm" and "out of range" in str(e.value)
    with pytest.raises(InputError) as e:
        B.build_geometry("subject_ankle", {"talar_radius_mm": 40.0})
    assert "17" in str(e.value) and "24" in str(e.value)
    with pytest.raises(InputError) as e:
        B.build_geometry("subject_ankle", {"depression_positions": [[1.0, 2.0]]})
    assert e.value.key == "geometry.depression_positions"
    with pytest.raises(InputError) as e:
        B.build_geometry("ideal_ankle", {"cartilage": False, "plafond_tilt_deg": 10.0}, file="scene.toml")
    assert e.value.file == "scene.toml" and e.value.key == "geometry.plafond_tilt_deg"
    # a parameter of the other mode is refused, naming it and the mode it belongs to
    with pytest.raises(InputError) as e:
        B.build_geometry("ideal_ankle", {"plafond_gap_mm": 2.0}, file="scene.toml")
    assert e.value.key == "geometry.plafond_gap_mm" and "cartilage = false" in str(e.value)
    with pytest.raises(InputError) as e:
        B.build_geometry("subject_ankle", {"cartilage": False, "talar_cartilage_mm": 1.2})
    assert e.value.key == "geometry.talar_cartilage_mm" and "cartilage = true" in str(e.value)
    with pytest.raises(InputError) as e:
        B.build_geometry("ideal_ankle", {"cartilage_taper_mm": 15.0, "mesh_size_mm": 4.0})
    assert e.value.key == "geometry.cartilage_taper_mm" and "at most 14 mm" in str(e.value)
    with pytest.raises(InputError) as e:
        B.build_geometry("ideal_ankle", {"incongruity": 0.0})
    assert e.value.key == "geometry.incongruity" and "out of range" in str(e.value)


def test_no_gmsh_or_pyvista_for_scenes_that_need_no_meshing():
    code = (
        "import sys; from geometries.builders import build_geometry;"
        "build_geometry('flat_plates', {}); build_geometry('tilted_plane', {});"
        "build_geometry('hemispheres', {'reference_subdivisions': 2});"
        "import geometries.fe_solids, geometries.render;"
        "assert 'gmsh' not in sys.modules and 'pyvista' not in sys.modules"
        " and 'dolfinx' not in sys.modules, sorted(sys.modules)"
    )
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)


def test_builder_inside_an_existing_gmsh_session_leaves_it_alone():
    gmsh = pytest.importorskip("gmsh")
    gmsh.initialize(interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("caller")
        gmsh.option.setNumber("Mesh.Algorithm", 5)
        B.ideal_ankle(mesh_size_mm=3.0)
        assert gmsh.isInitialized()
        assert gmsh.model.getCurrent() == "caller"
        assert gmsh.option.getNumber("Mesh.Algorithm") == 5
    finally:
        gmsh.finalize()


# --------------------------------------------------------------------------------------------
# FE solids
# --------------------------------------------------------------------------------------------


def _top_points(solid: F.FESolid, n_bottom: int) -> tuple[np.ndarray, np.ndarray]:
    top_layer = solid.layer.max()
    bottom = np.empty((n_bottom, 3))
    top = np.empty((n_bottom, 3))
    bottom[solid.bottom_vertex[solid.layer == 0]] = solid.points_mm[solid.layer == 0]
    top[solid.bottom_vertex[solid.layer == top_layer]] = solid.points_mm[solid.layer == top_layer]
    return bottom, top


def test_slab_thickness_at_centroids_equals_spring_length_on_tilted_plate():
    g = B.tilted_plane(width_mm=12.0, depth_mm=8.0, gap_mm=2.0, tilt_deg=4.0, n_per_side=9)
    h = 2.0 + g.mobile.centroids_mm[:, 0] * math.tan(math.radians(4.0))
    slab = F.slab_solid(g.mobile, h, 3.5, layers_through_thickness=3)
    bottom, top = _top_points(slab, len(g.mobile.vertices_mm))
    # every triangle is a candidate, so the submesh keeps the vertex order of the plate
    np.testing.assert_array_equal(bottom, g.mobile.vertices_mm)
    thickness_at_centroid = (top - bottom)[g.mobile.triangles].mean(axis=1)
    np.testing.assert_allclose(thickness_at_centroid[:, :2], 0.0, atol=1e-12)  # along the normal
    np.testing.assert_allclose(thickness_at_centroid[:, 2], h, rtol=1e-9)
    # the top face is the tilted plane itself
    np.testing.assert_allclose(top[:, 2], 2.0 + top[:, 0] * math.tan(math.radians(4.0)),
                               rtol=1e-9)
    assert np.all(slab.volumes_mm3 > 0)
    assert slab.volumes_mm3.sum() == pytest.approx(float(h @ g.mobile.areas_mm2), rel=1e-12)


def test_slab_only_on_candidates_and_top_on_the_plafond(ideal_flat):
    h = _plane_ray_lengths(ideal_flat.mobile, ideal_flat.fixed, 0)
    slab = F.slab_solid(ideal_flat.mobile, h, 3.5, layers_through_thickness=2)
    cand = h <= 3.5
    assert np.all(slab.volumes_mm3 > 0)
    p = slab.points_mm[slab.faces(F.BONDED_TAG)]
    bonded_area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum()
    assert bonded_area == pytest.approx(ideal_flat.mobile.areas_mm2[cand].sum(), rel=1e-12)
    top = slab.points_mm[slab.layer == slab.layer.max()]
    # vertex lengths are reconstructed from centroid values: within 1 % of h_max of the plane
    assert np.abs(top[:, 2] - 1.5).max() < 0.035


def test_layer_thickness_is_t_along_vertex_normals(ideal):
    layer = F.layer_solid(ideal.mobile, 1.75, layers_through_thickness=2)
    bottom, top = _top_points(layer, len(ideal.mobile.vertices_mm))
    np.testing.assert_allclose(np.linalg.norm(top - bottom, axis=1), 1.75, rtol=1e-12)
    radial = bottom - np.array([0.0, 0.0, -20.0])
    radial[:, 0] = 0.0
    # on the cylinder the offset is radial (vertex normals of an inscribed mesh)
    d = (top - bottom) / 1.75
    assert np.all(np.einsum("ij,ij->i", d, radial / np.linalg.norm(radial, axis=1)[:, None])
                  > 0.999)
    assert np.all(layer.volumes_mm3 > 0)
    exact = 28.0 * math.radians(114.0) * ((20 + 1.75) ** 2 - 20**2) / 2
    assert layer.volumes_mm3.sum() == pytest.approx(exact, rel=2e-3)


def test_fe_solids_positive_volumes_conforming_and_physical_groups(tmp_path, ideal):
    h = _plane_ray_lengths(ideal.mobile, ideal.fixed, 0)
    solids = [
        F.slab_solid(ideal.mobile, h, 3.5, mesh_size_mm=0.5, layers_through_thickness=3),
        F.layer_solid(B.subject_ankle(mesh_size_mm=2.0).mobile, 1.75),
    ]
    for solid in solids:
        assert np.all(solid.volumes_mm3 > 0)
        # conforming: every interior face shared by exactly two tets, boundary = tagged facets
        t = solid.tets
        faces = np.sort(np.concatenate([t[:, [1, 2, 3]], t[:, [0, 2, 3]], t[:, [0, 1, 3]],
                                        t[:, [0, 1, 2]]]), axis=1)
        _, counts = np.unique(faces, axis=0, return_counts=True)
        assert counts.max() == 2
        assert (counts == 1).sum() == len(solid.facets)
        for tag in (F.BONDED_TAG, F.CONTACT_TAG, F.FREE_TAG):
            assert (solid.facet_tags == tag).sum() > 0
        # facets point outward: divergence theorem, sum of x . n dA / 3 over them = volume
        p = solid.points_mm[solid.facets]
        flux = np.einsum("ij,ij->i", p.mean(axis=1),
                         0.5 * np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])).sum() / 3.0
        assert flux == pytest.approx(solid.volumes_mm3.sum(), rel=1e-9)
    gmsh = pytest.importorskip("gmsh")
    path = solids[0].write_msh(tmp_path / "slab.msh")
    gmsh.initialize(interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.open(str(path))
        groups = {tag: dim for dim, tag in gmsh.model.getPhysicalGroups()}
        assert groups == {1: 2, 2: 2, 3: 2, 10: 3}
        for tag, dim in groups.items():
            ents = gmsh.model.getEntitiesForPhysicalGroup(dim, tag)
            n = sum(len(gmsh.model.mesh.getElements(dim, int(e))[1][0]) for e in ents)
            tags = solids[0].facet_tags
            expected = len(solids[0].tets) if tag == 10 else int((tags == tag).sum())
            assert n == expected > 0
    finally:
        gmsh.finalize()


@pytest.mark.fe
def test_msh_and_arrays_load_in_dolfinx_with_tags(tmp_path):
    pytest.importorskip("dolfinx_solver")
    g = B.tilted_plane(width_mm=6.0, depth_mm=6.0, gap_mm=2.0, tilt_deg=3.0, n_per_side=4)
    h = 2.0 + g.mobile.centroids_mm[:, 0] * math.tan(math.radians(3.0))
    slab = F.slab_solid(g.mobile, h, 3.5, layers_through_thickness=2)
    path = slab.write_msh(tmp_path / "slab.msh")

    import dolfinx_solver  # noqa: F401

    import dolfinx.io.gmsh
    from mpi4py import MPI

    data = dolfinx.io.gmsh.read_from_msh(str(path), MPI.COMM_SELF, gdim=3)
    assert data.mesh.topology.index_map(3).size_local == len(slab.tets)
    vals, counts = np.unique(data.facet_tags.values, return_counts=True)
    assert dict(zip(vals.tolist(), counts.tolist())) == {
        tag: int((slab.facet_tags == tag).sum()) for tag in (1, 2, 3)}
    assert set(data.cell_tags.values.tolist()) == {10}
    assert set(data.physical_groups) == {"bonded", "contact", "free", "cartilage"}

    mesh, cell_tags, facet_tags = slab.to_dolfinx(MPI.COMM_SELF)
    assert mesh.topology.index_map(3).size_local == len(slab.tets)
    vals2, counts2 = np.unique(facet_tags.values, return_counts=True)
    assert np.array_equal(vals2, vals) and np.array_equal(counts2, counts)
    assert set(cell_tags.values.tolist()) == {10}
    import dolfinx.fem
    import ufl

    one = dolfinx.fem.form(1.0 * ufl.dx(domain=mesh))
    assert dolfinx.fem.assemble_scalar(one) == pytest.approx(float(h @ g.mobile.areas_mm2),
                                                              rel=1e-12)


# --------------------------------------------------------------------------------------------
# render
# --------------------------------------------------------------------------------------------


def test_render_png_written_and_not_blank(tmp_path, ideal):
    pytest.importorskip("pyvista")
    from PIL import Image

    from geometries.render import render_geometry_png

    h = _plane_ray_lengths(ideal.mobile, ideal.fixed, 0)
    path = render_geometry_png(ideal, tmp_path / "ideal.png", spring_length_mm=h,
                               window_size=(400, 300))
    assert path.exists() and path.stat().st_size > 0
    img = np.asarray(Image.open(path), dtype=np.float64)
    assert img.shape[:2] == (300, 400)
    assert img.var() > 0


def lip_patch(lip_deg: float, lip_mm: float = 1.0, n: int = 10, size_mm: float = 10.0) -> TriangleSurface:
    """A flat 10 x 10 mm grid (z = 0, normals +z) whose x = 10 edge carries a 1 mm strip folded
    down and back by ``lip_deg``: the rim of a segmented surface, where vertex normals lean."""
    xs = np.linspace(0.0, size_mm, n + 1)
    xx, yy = np.meshgrid(xs, xs, indexing="ij")
    v = np.column_stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)])
    idx = np.arange(xx.size).reshape(xx.shape)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    edge = idx[-1, :]
    angle = np.radians(lip_deg)
    lip = np.column_stack([np.full(n + 1, size_mm + lip_mm * np.cos(angle)), xs, np.full(n + 1, -lip_mm * np.sin(angle))])
    li = len(v) + np.arange(n + 1)
    tris = [np.column_stack([a, b, c]), np.column_stack([a, c, d]),
            np.column_stack([edge[:-1], li[:-1], li[1:]]), np.column_stack([edge[:-1], li[1:], edge[1:]])]
    return TriangleSurface(np.vstack([v, lip]), np.vstack(tris))


@pytest.mark.parametrize("model", ["layer", "slab"])
def test_fe_solid_drops_rim_triangles_whose_prisms_would_invert(model):
    """A rim strip folded back 120 deg: extruded 2 mm along the vertex normals, a rim prism turned
    inside out and the whole build failed ("surface too curved"). The rim triangle is dropped,
    warned with its index and lean, and every tetrahedron of the solid is positive."""
    surface = lip_patch(120.0)
    with pytest.warns(UserWarning, match=r"1 rim triangles dropped .*triangles 90\).*lean up to \d+ deg"):
        if model == "layer":
            solid = F.layer_solid(surface, 2.0, layers_through_thickness=2)
        else:
            solid = F.slab_solid(surface, np.full(surface.n_triangles, 2.0), 3.5, layers_through_thickness=2)
    assert np.all(solid.volumes_mm3 > 0)
    # the flat part is all there: 200 triangles x 2 layers x 3 tetrahedra at least
    assert len(solid.tets) >= 200 * 2 * 3


def test_fe_solid_refuses_naming_the_triangles_it_cannot_extrude():
    """Folded back 160 deg, dropping rim triangles does not stop the inversion: refused, naming the
    triangles of the mobile surface and how far their vertex normals lean."""
    with pytest.raises(ValueError, match=r"turn inside out .*triangles \d+.*of the mobile surface.*lean up to \d+ deg"):
        F.layer_solid(lip_patch(160.0), 2.0, layers_through_thickness=2)


def test_fe_models_report_dropped_rim_triangles_and_refuse_with_solver_error():
    """The FE models pass the construction's warnings on to the run (summary.json) and turn a
    solid that cannot be built into a SolverError (exit 2) naming the triangles."""
    from fem_reference.models import _build_solid
    from geometries.errors import SolverError

    solid, notes = _build_solid("layer", lambda: F.layer_solid(lip_patch(120.0), 2.0, layers_through_thickness=2))
    assert np.all(solid.volumes_mm3 > 0) and any("rim triangles dropped" in n for n in notes)
    with pytest.raises(SolverError, match=r"building the FE layer failed: .*triangles \d+"):
        _build_solid("layer", lambda: F.layer_solid(lip_patch(160.0), 2.0, layers_through_thickness=2))
