"""JointReaction loads in the solver: moments moved from the joint centre to G, turned with the
fixed body, and never dropped silently on fixed rotations."""

from __future__ import annotations

import numpy as np
import pytest
from support import grid_plate, make_scene, plane

from edem.loads import JointKinematics, LoadSeries
from edem.solver import run


def plates_with_load(load: LoadSeries, fixed_dofs=("tx", "ty", "rz"), **extra):
    scene = make_scene(grid_plate(20, 20, 10), plane(lambda x, y: 2.0, size_mm=30.0), [0, 0, 1.0], fixed_dofs=fixed_dofs, **extra)
    return scene.__class__(**{**scene.__dict__, "load": load})


def test_force_through_the_joint_centre_puts_the_centre_of_pressure_there():
    """400 N given about P = (3, -2, 5) mm with zero moment there: moved to G = 0 it is
    M_G = (P - G) x F, and the springs' resultant acts through P: the centre of pressure of the
    bed on flat plates is (3, -2) (moment balance about G, whatever springs lift off)."""
    p = np.array([[3.0, -2.0, 5.0]])
    load = LoadSeries(np.zeros(1), np.array([[0.0, 0.0, 400.0]]), np.zeros((1, 3)), point_mm=p)
    scene = plates_with_load(load, reference_point_mm=np.zeros(3))
    np.testing.assert_allclose(scene.applied_loads()[0, 3:], np.cross(p[0], [0.0, 0.0, 400.0]), rtol=1e-12)
    step = run(scene, "dem").steps[0]
    force = step.pressure_mpa * step.area_mm2
    centroids = scene.spring_centroid_mm
    centre = (force[:, None] * centroids).sum(axis=0) / force.sum()
    np.testing.assert_allclose(centre[:2], p[0, :2], atol=1e-9)  # round-off of a 200-spring sum


def test_joint_centre_given_in_the_fixed_frame_turns_with_the_fixed_body():
    """frame = "fixed": F, M_P and P all turn with F (30 deg about z through (1, 0, 0)) before the
    moment is moved to G."""
    angle = np.radians(30.0)
    kin = JointKinematics(np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0]), np.array([angle]))
    f, m, p = np.array([10.0, 0.0, 400.0]), np.array([0.0, 1000.0, 0.0]), np.array([2.0, 0.0, 4.0])
    load = LoadSeries(np.zeros(1), f[None], m[None], frame="fixed", point_mm=p[None])
    scene = plates_with_load(load, kinematics=kin, reference_point_mm=np.zeros(3))
    c, s = np.cos(angle), np.sin(angle)
    r = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    p_global = r @ (p - [1.0, 0, 0]) + [1.0, 0, 0]
    expected = np.concatenate([r @ f, r @ m + np.cross(p_global, r @ f)])
    np.testing.assert_allclose(scene.applied_loads()[0], expected, rtol=1e-12, atol=1e-9)


def test_moment_on_fixed_rotations_is_warned_not_dropped_silently():
    load = LoadSeries(np.zeros(1), np.array([[0.0, 0.0, 400.0]]), np.array([[250.0, 0.0, 0.0]]))
    result = run(plates_with_load(load, fixed_dofs=("tx", "ty", "rx", "ry", "rz")), "dem")
    assert any("about rx (up to 250 N mm)" in w and "fixed_dofs" in w for w in result.warnings)
    free = run(plates_with_load(load, fixed_dofs=("tx", "ty", "rz")), "dem")
    assert not any("applied moment" in w for w in free.warnings)
