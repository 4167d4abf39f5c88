"""Equilibria outside the measured geometry are refused, naming the DOF and the amount (exit 2).

Any law, DEM and EDEM, with and without ligaments: a slide or turn beyond the ray window, or
contact lost under a load that pushes the bodies together.
"""

from __future__ import annotations

import numpy as np
import pytest
from support import grid_plate, make_scene, plane

from edem.cli import main
from edem.beds import IndependentSprings
from edem.consistency import check_increment, describe_motion, motion_bound_mm, point_motion_mm
from geometries.errors import SolverError
from edem.loads import JointKinematics
from edem.solver import run
from edem.springs import Cartilage, Ligament
from geometries.builders import build_geometry
from geometries.mesh_files import write_surface

ROTATIONS = ("rx", "ry", "rz")


@pytest.fixture(scope="module")
def ankle():
    return build_geometry("ideal_ankle", {"cartilage": False})  # the thesis's cylinder under a plane


def ankle_ligaments(ankle) -> tuple[Ligament, ...]:
    """The built-in ankle's four ligaments, slack length = the initial distance (thesis modulus)."""
    return tuple(
        Ligament(lig.name, lig.mobile_point_mm, lig.fixed_point_mm, 255.0, 10.0, float(np.linalg.norm(lig.fixed_point_mm - lig.mobile_point_mm)))
        for lig in ankle.ligaments
    )


def test_describe_motion_names_dofs_largest_first_in_mm_and_deg():
    # ordered by the motion each causes 10 mm from G: 65 mm > 15.7 mm > 1 mm
    assert describe_motion(np.array([0.0, 65.0, 0.0, 0.0, 0.0, np.pi / 2])) == "ty +65 mm, rz +90 deg"
    assert describe_motion(np.array([1.0, 0.0, 0.0, 0.0, 0.0, -np.pi / 2])) == "rz -90 deg, tx +1 mm"
    assert describe_motion(np.zeros(6)) == "no motion"


def test_point_motion_of_a_finite_rotation_is_the_chord():
    """A quarter turn about G moves a point at 10 mm by the chord 10 sqrt(2) mm (not 10 pi / 2)."""
    moved = point_motion_mm(np.array([0, 0, 0, 0, 0, np.pi / 2]), np.array([[10.0, 0, 0]]), np.zeros(3))
    assert moved[0] == pytest.approx(10.0 * np.sqrt(2.0), rel=1e-12)


def test_motion_bound_holds_every_point_and_is_reached():
    """|u_G| + 2 sin(|q|/2) r bounds the motion of every point within r of G (random motions up
    to half a turn), and is reached by a point at distance r perpendicular to the axis when u_G
    lies along that point's chord; check_increment's answer does not depend on the bound."""
    rng = np.random.default_rng(2)
    points = rng.normal(size=(500, 3)) * 20.0
    r = float(np.linalg.norm(points, axis=1).max())
    for _ in range(200):
        u = np.r_[rng.normal(size=3) * rng.uniform(0, 5), rng.normal(size=3) * rng.uniform(0, 1)]
        assert point_motion_mm(u, points, np.zeros(3)).max() <= motion_bound_mm(u, r) * (1 + 1e-12)
    # a quarter turn about z with u_G along the chord of (r, 0, 0): (-r, r, 0) / sqrt(2) direction
    chord = np.array([-1.0, 1.0, 0.0]) / np.sqrt(2.0)
    u = np.r_[2.0 * chord, 0.0, 0.0, np.pi / 2]
    exact = point_motion_mm(u, np.array([[10.0, 0.0, 0.0]]), np.zeros(3))[0]
    assert exact == pytest.approx(motion_bound_mm(u, 10.0), rel=1e-12)
    # refused with and without the bound (the bound only decides whether to measure)
    cartilage = Cartilage(1.0, 0.3, max_spring_length_mm=3.5, coupling=IndependentSprings.coupling, bed_keys=IndependentSprings.Keys())
    big = np.r_[0.0, 0.0, 0.0, 0.0, 0.0, 0.5]  # moves (10, 0, 0) by 10 * 2 sin(0.25) = 4.9 mm > 3.5
    for bound in (np.inf, 10.0):
        with pytest.raises(SolverError, match="more than 1 x the ray window"):
            check_increment(big, np.array([[10.0, 0.0, 0.0], [1.0, 0, 0]]), np.zeros(3), cartilage, "here", arm_bound_mm=bound)
        check_increment(big, np.array([[10.0, 0.0, 0.0], [1.0, 0, 0]]), np.zeros(3), cartilage, "here", arm_bound_mm=bound,
                        in_contact=np.array([False, True]))  # only the spring at 1 mm is in contact: 0.49 mm


@pytest.mark.parametrize("method", ["dem", "edem"])
def test_slide_along_the_ankle_axis_under_a_side_load_is_refused(ankle, method):
    """The faceted ideal talus barely resists sliding along its axis: 1 N along it with 333 N down
    slid it 65 mm (off the 28 mm wide plafond) with only a stiffness warning. Refused, naming tx.
    With the ankle's ligaments (or tx fixed) the same load is held inside the window."""
    scene = make_scene(ankle.mobile, ankle.fixed, [1.0, 0.0, 333.0], fixed_dofs=ROTATIONS)
    with pytest.raises(SolverError, match=r"moves the mobile body by tx \+6\d(\.\d+)? mm.*ray window h_max = 3.5 mm"):
        run(scene, method)
    held = run(make_scene(ankle.mobile, ankle.fixed, [1.0, 0.0, 333.0], fixed_dofs=ROTATIONS, ligaments=ankle_ligaments(ankle)), method)
    assert 0 < held.steps[0].displacement_mm[0] < 0.5 and held.steps[0].contact_area_mm2 > 0
    fixed = run(make_scene(ankle.mobile, ankle.fixed, [1.0, 0.0, 333.0], fixed_dofs=("tx",) + ROTATIONS), method)
    assert fixed.steps[0].contact_area_mm2 > 0


@pytest.mark.parametrize("law", ["threshold", "gap", "gap-log"])
def test_shear_sliding_on_flat_plates_is_refused_for_every_law(law):
    """100 N of shear on plates with a soft shear bed (G = 1e-3 MPa, 0.2 N/mm over 400 mm^2) slides
    the mobile plate 500 mm: refused naming tx and the amount, for each law."""
    scene = make_scene(
        grid_plate(20, 20, 10), plane(lambda x, y: 1.0, size_mm=30.0), [100.0, 0.0, 400.0], law=law,
        thickness_mm=2.0, max_spring_length_mm=3.0, shear_modulus_mpa=1e-3, fixed_dofs=("ty",) + ROTATIONS,
    )
    with pytest.raises(SolverError, match=r"moves the mobile body by tx \+\d+"):
        run(scene, "dem")


def test_fixed_body_turned_away_with_the_talus_held_by_ligaments_is_refused(ankle):
    """The tibia turned 90 deg about the ankle axis: no contact, the 300 N pushing the talus up is
    held by the ligaments alone 22 mm away. Refused for DEM and EDEM, naming the motion."""
    kinematics = JointKinematics(np.array([0.0, 0.0, -20.0]), np.array([1.0, 0.0, 0.0]), np.radians([0.0, 90.0]))
    scene = make_scene(
        ankle.mobile, ankle.fixed, [[0.0, 0.0, 300.0]] * 2, fixed_dofs=("tx",) + ROTATIONS,
        ligaments=ankle_ligaments(ankle), kinematics=kinematics,
    )
    for method in ("dem", "edem"):
        with pytest.raises(SolverError, match=r"time point 1 .*no spring is in contact.*moves it by tz -2\d\.\d mm, ty -1\d\.\d mm"):
            run(scene, method)


def test_ligaments_holding_a_distraction_load_are_a_valid_equilibrium(ankle):
    """Pulling the talus down (away from the tibia) with ligaments: no contact, but nothing pushes
    the bodies together, so the equilibrium stands and the ligaments carry the whole load."""
    scene = make_scene(ankle.mobile, ankle.fixed, [0.0, 0.0, -50.0], fixed_dofs=("tx",) + ROTATIONS, ligaments=ankle_ligaments(ankle))
    step = run(scene, "dem").steps[0]
    assert step.contact_area_mm2 == 0.0
    assert step.ligament_force_n.sum() > 50.0 * (1 - 1e-9)  # inclined ligaments: their sum >= the load


@pytest.mark.parametrize("name", ["ideal-stance", "subject-stance", "ideal-toe-off"])
@pytest.mark.parametrize("method", ["dem", "edem"])
def test_builtin_stances_stay_inside_the_window_under_both_methods(name, method):
    """The thesis's stances move their contact springs by at most about half the window per solve
    (DEM at the ideal toe off: 0.53 h_max): none is refused under either method."""
    from edem.scene import load_scene

    scene = load_scene(name)
    result = run(scene, method)
    assert len(result.steps) == len(scene.load.time_s)
    # every solve balanced its load (the solver's own round-off tolerance, 1e-10 relative)
    assert max(s.force_residual_n for s in result.steps) <= 1e-8 * (1.0 + float(np.abs(scene.load.force_n).max()))


def test_cli_refuses_with_exit_2_naming_the_dof(tmp_path, capsys):
    """`edem run` on plates with a soft shear bed and a large shear load: exit 2, no traceback,
    the message names tx and its amount."""
    write_surface(tmp_path / "talus.stl", grid_plate(20, 20, 10))
    write_surface(tmp_path / "tibia.stl", plane(lambda x, y: 2.0, size_mm=30.0))
    (tmp_path / "s.toml").write_text(
        """[geometry]
mobile = "talus.stl"
fixed = "tibia.stl"
[cartilage]
youngs_modulus_mpa = 10.35
poissons_ratio = 0.42
shear_modulus_mpa = 0.001
[load]
force_n = [100.0, 0.0, 400.0]
[constraints]
fixed_dofs = ["ty", "rx", "ry", "rz"]
""",
        encoding="utf-8",
    )
    assert main(["run", str(tmp_path / "s.toml"), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "no solution" in err and "tx +500 mm" in err and "Traceback" not in err
