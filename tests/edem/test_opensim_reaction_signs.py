"""JointReaction signs against OpenSim itself: the .sto OpenSim writes drives `edem run`, and the
contact must balance the load that OpenSim's joint carried (README.md#from-an-opensim-model,
docs/conventions.md#signs).

The two-body model of tests/opensim_fixtures.py (a talar dome on a CustomJoint under a tibial
plate welded to ground) gets one external load on the talus, a PrescribedForce, and no gravity;
the motion holds the joint still, so by the talus's equilibrium OpenSim's reaction on the talus
is minus that load, and the contact that replaces the joint must carry the load itself.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("opensim")
from opensim_fixtures import GAIT2392, add_prescribed_force, build_model, gait2392_ankle_reaction, run_joint_reaction, write_motion  # noqa: E402

from edem.cli import main  # noqa: E402
from edem.joint_reaction import axes_matrix  # noqa: E402
from edem.loads import read_opensim_table  # noqa: E402
from edem.resultdir import read_timeseries_csv  # noqa: E402
from edem.scene import load_scene  # noqa: E402

pytestmark = pytest.mark.opensim
END_TIME_S = 1.0
N_TIMES = 11  # OpenSim's coordinate splines need at least 6 rows
PUSH_N = ((0.0, 0.0), (200.0, 800.0), (0.0, 0.0))  # up (+y) into the tibia, ramping 200 -> 800 N
POINT_M = (0.0, 0.0, 0.005)  # 5 mm along the dome's axis from the joint centre: a moment about x too


def external_load(time_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The PrescribedForce (N, talus frame = scene frame) and its point (mm) at each time."""
    force = np.column_stack([np.interp(time_s, [0.0, END_TIME_S], f) for f in PUSH_N])
    return force, np.tile(np.array(POINT_M) * 1000.0, (len(time_s), 1))


@pytest.fixture(scope="module")
def loaded_model(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("jr")
    build_model(folder)
    add_prescribed_force(folder / "two_body_ankle.osim", folder / "loaded.osim", "talus", PUSH_N, POINT_M, END_TIME_S)
    time = np.linspace(0.0, END_TIME_S, N_TIMES)
    write_motion(folder / "still.mot", time, np.zeros(N_TIMES), np.zeros(N_TIMES))
    return folder


def scene_text(reaction: Path) -> str:
    return f"""[scene]
name = "jr-signs"
[opensim]
model = "loaded.osim"
mobile_body = "talus"
fixed_body = "tibia"
motion = "still.mot"
[cartilage]
youngs_modulus_mpa = 10.35
poissons_ratio = 0.42
max_spring_length_mm = 3.5
[load]
file = "{reaction}"
axes = "same"
mobile_body = "talus"
fixed_body = "tibia"
[constraints]
fixed_dofs = ["tx", "tz", "ry", "rz"]  # what a frictionless cylinder under a plane cannot resist
[solver]
method = "edem"
"""


@pytest.mark.parametrize("on_body, in_frame", [("child", "parent"), ("parent", "child"), ("child", "ground")])
def test_contact_balances_the_external_load_opensim_s_joint_carried(loaded_model, tmp_path, on_body, in_frame):
    """The reaction on the talus (negated) or on the tibia (as is), in either body or in ground, as
    OpenSim wrote it: the contact resultant equals the external load on the talus, force (ty) and
    moment about G (rx, the joint centre's moment moved to G), at every time point; the other
    DOFs are held by the constraints and see nothing.

    Tolerance: 1e-6 of the load. The load passes through OpenSim's .sto with 8 decimals (1e-8 N
    and 1e-8 N m on 200 N and 1 N m) and EDEM balances each step to 1e-10 of the load: anything
    bigger than round-off is an error (a sign error misses by 200 %, the issue's bound is 1 %)."""
    reaction = run_joint_reaction(loaded_model / "loaded.osim", loaded_model / "still.mot", "ankle", on_body, in_frame,
                                  tmp_path / "opensim", (0.0, END_TIME_S))
    body = "talus" if on_body == "child" else "tibia"
    frame = {"child": "talus", "parent": "tibia", "ground": "ground"}[in_frame]
    assert reaction.read_text().count(f"ankle_on_{body}_in_{frame}_fx") == 1
    scene_file = loaded_model / f"jr_{on_body}_{in_frame}.toml"
    scene_file.write_text(scene_text(reaction), encoding="utf-8")
    assert main(["run", str(scene_file), "--out", str(tmp_path / "out")]) == 0
    series = read_timeseries_csv(tmp_path / "out" / "timeseries.csv")
    force, point = external_load(series["time_s"])
    g = load_scene(scene_file).reference_point_mm
    moment = np.cross(point - g, force)  # N mm about G
    contact_force = np.column_stack([series[f"contact_force_{c}_n"] for c in "xyz"])
    contact_moment = np.column_stack([series[f"contact_moment_{c}_nmm"] for c in "xyz"])
    scale = np.abs(force).max()
    np.testing.assert_allclose(contact_force[:, 1], force[:, 1], rtol=1e-6)
    np.testing.assert_allclose(contact_moment[:, 0], moment[:, 0], atol=1e-6 * scale * 10.0)  # arm ~10 mm
    assert np.all(series["contact_area_mm2"] > 0)


LOADED_N = 1000.0  # "loaded instant": the bound; stance loads reach 3-6 body weights (4 kN)


@pytest.mark.skipif(not GAIT2392.is_dir(), reason=f"public OpenSim data not at {GAIT2392}")
def test_gait2392_reaction_presses_the_ideal_ankle_into_contact_and_the_contact_balances_minus_it(tmp_path):
    """subject01's walk through OpenSim's static optimisation and JointReaction (ankle_r on the
    talus, in the tibia) drives the built-in ideal ankle (the ideal stance's constraints, no
    ligaments, so only the contact carries the load; the IK's ankle angle turns the tibia): every
    instant over 1 kN is in contact,
    and on the free DOFs (ty, tz) the contact resultant equals minus the reaction turned into the
    scene (OpenSim x anterior, y up, z right onto x right, y anterior, z up; then the tibia's
    rotation by the ankle angle about -x). Before the sign fix the run was refused as pulling the
    bodies apart (with the stance's ligaments the talus hung 8.5 mm from them, no contact at 3.7 kN).

    Tolerance: 1e-6 of the peak load. EDEM balances every step to 1e-10 of the load and nothing
    but the contact and the constraints (tx, rotations) carries it, so only round-off separates them."""
    reaction = gait2392_ankle_reaction(tmp_path / "opensim")
    table = read_opensim_table(reaction, "reaction")
    prefix = "ankle_r_on_talus_r_in_tibia_r"
    force_in_tibia = np.column_stack([table.column(f"{prefix}_f{c}", "reaction") for c in "xyz"])
    scene = tmp_path / "gait.toml"
    scene.write_text(f"""[scene]
name = "gait2392-ideal-ankle"
[geometry]
builtin = "ideal_ankle"
cartilage = false
[cartilage]
youngs_modulus_mpa = 10.35
poissons_ratio = 0.42
max_spring_length_mm = 3.5
[load]
file = "{reaction}"
axes = "opensim"
mobile_body = "talus_r"
fixed_body = "tibia_r"
[kinematics]
file = "{GAIT2392 / 'subject01_walk1_ik.mot'}"
angle_column = "ankle_angle_r"
axis_point_mm = [0.0, 0.0, -20.0]
axis_direction = [-1.0, 0.0, 0.0]
[constraints]
fixed_dofs = ["tx", "rx", "ry", "rz"]
[solver]
method = "edem"
""", encoding="utf-8")
    assert main(["run", str(scene), "--out", str(tmp_path / "out")]) == 0
    series = read_timeseries_csv(tmp_path / "out" / "timeseries.csv")
    np.testing.assert_allclose(series["time_s"], table.column("time", "reaction"))
    angle = np.radians(series["joint_angle_deg"])
    # the tibia turns by the angle about -x: R_x(-angle) carries its axes into the scene's
    c, s = np.cos(angle), np.sin(angle)
    turn = np.zeros((len(angle), 3, 3))
    turn[:, 0, 0], turn[:, 1, 1], turn[:, 1, 2], turn[:, 2, 1], turn[:, 2, 2] = 1.0, c, s, -s, c
    pressing = -np.einsum("kij,kj->ki", turn, force_in_tibia @ axes_matrix("opensim").T)
    contact = np.column_stack([series[f"contact_force_{c}_n"] for c in "xyz"])
    loaded = np.linalg.norm(force_in_tibia, axis=1) > LOADED_N
    assert loaded.sum() >= 30  # most of the 48 stance rows carry more than 1 kN
    assert np.all(series["contact_area_mm2"][loaded] > 0)
    np.testing.assert_allclose(contact[loaded, 1:], pressing[loaded, 1:], atol=1e-6 * np.abs(pressing).max())
