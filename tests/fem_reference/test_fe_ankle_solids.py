"""The FE solids of the built-in ankles' cartilage (fem_reference.models, geometries.cartilage_solids):
each layer tapers to zero on its bone at its margin (docs/method.md#8-built-in-geometries), and the
FE solid follows it there instead of refusing or smoothing it.

Invariants: every column under M's contact face is as tall as the thickness measured to the bone by
the ray the springs' triangles are measured with (the springs and the FE see one cartilage), a
vertex on its bone has a column of no height (one point, on both faces) and not the thickness of
the unmeasured triangles, every tetrahedron has a positive volume, on every mesh level of the
convergence study.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from edem.scene import load_scene
from fem_reference.models import FE_MODELS, _measured_thickness, column_directions, scene_layer_solid
from geometries.fe_solids import BONDED_TAG, FIXED_BONDED_TAG, FIXED_CONTACT_TAG, CONTACT_TAG, tet_volumes


@pytest.fixture(scope="module", params=["ideal-standing", "subject-standing"])
def scene(request):
    return load_scene(request.param)


def test_a_margin_vertex_on_its_bone_has_no_thickness_not_the_fallback(scene):
    """The talar margin's vertices lie on the talar bone (the taper's zero): 0 mm, where the ray cast
    finds no depth and the unmeasured value (the median, 1.3 mm) was taken before."""
    layer = scene.cartilage.layers.mobile
    v, t = scene.mobile.vertices_mm, scene.mobile.triangles
    edges = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    unique, count = np.unique(edges, axis=0, return_counts=True)
    margin = np.unique(unique[count == 1])
    from geometries.fe_solids import vertex_normals

    thickness = _measured_thickness(layer, layer.bone)(v[margin], -vertex_normals(v, t)[margin])
    # 1e-9 of the surface's extent: the round-off of coordinates that coincide by construction
    assert np.all(thickness <= 1e-9 * float(np.ptp(v, axis=0).max()))


@pytest.mark.parametrize("mesh_size_mm", [2.0, 1.0, 0.7])
def test_the_two_layer_solid_follows_the_taper_to_zero_on_every_level(scene, mesh_size_mm):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mobile = scene_layer_solid(scene, mesh_size_mm, None)
    assert not [w for w in caught if "smoothed" in str(w.message)]  # the measured thickness as it is
    solid = FE_MODELS["two-layer"]._paired(scene, mobile, scene.fixed_placement(0), None)
    assert np.all(tet_volumes(solid.points_mm, solid.tets) > 0)
    # M: every column as tall as the thickness measured down it (the springs' ray cast), 0 at the margin
    layer = scene.cartilage.layers.mobile
    direction, top = column_directions(mobile)
    height = np.linalg.norm(mobile.points_mm[top] - mobile.points_mm[mobile.bottom_vertex[top]], axis=1)
    measured = _measured_thickness(layer, layer.bone)(mobile.points_mm[top], -direction)
    zero = 1e-9 * float(np.ptp(scene.mobile.vertices_mm, axis=0).max())
    np.testing.assert_allclose(height, np.where(measured <= zero, 0.0, measured), atol=1e-12)
    collapsed = top[height == 0.0]
    assert collapsed.size > 0 and set(collapsed.tolist()) <= set(np.unique(mobile.faces(BONDED_TAG)).tolist())
    # F: likewise down to F's bone (its own smoothed normals), 0 only where F's articular point lies on it
    fixed = scene.cartilage.layers.fixed
    f_top = np.unique(solid.faces(FIXED_CONTACT_TAG))
    f_column = solid.points_mm[f_top] - solid.points_mm[solid.bottom_vertex[f_top]]
    f_height = np.linalg.norm(f_column, axis=1)
    tall = f_height > 0.0
    f_measured = _measured_thickness(fixed, fixed.bone)(solid.points_mm[f_top[tall]], -f_column[tall] / f_height[tall, None])
    np.testing.assert_allclose(f_height[tall], f_measured, atol=1e-12)
    assert np.all(np.isin(solid.bottom_vertex[f_top], np.unique(solid.faces(FIXED_BONDED_TAG))))
    assert len(solid.faces(CONTACT_TAG)) > 0
