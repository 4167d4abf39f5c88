"""A new user's mix-ups said before they become a plausible exit 0 (edem/plausibility.py,
docs/conventions.md#plausibility-checks): moduli and loads in the wrong unit, bodies that look
swapped, warnings repeated at every time point, the Python warning class, `[load] max_step_s`,
and every `[load]` key documented."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from support import grid_plate, make_scene, plane

import edem
from geometries.errors import InputError
from edem.loads import LOAD_KEYS
from edem.scene import load_scene
from edem.solver import run

ROOT = Path(__file__).resolve().parents[2]
STANCE_PEAK_N = 4081.6  # the ideal stance's largest force (edem/scenes/ideal-stance.toml)


def said(scene, text: str) -> bool:
    return any(text in w for w in scene.warnings)


def test_a_modulus_in_pa_is_warned_and_one_in_mpa_is_not():
    """10.35 MPa written in Pa (1.035e7) gives springs a million times too stiff and an exit 0."""
    assert said(load_scene("ideal-standing", {"cartilage.youngs_modulus_mpa": 1.035e7}), "looks like Pa")
    assert said(load_scene("ideal-standing", {"cartilage.youngs_modulus_mpa": 0.01035}), "looks like GPa")
    assert not said(load_scene("ideal-standing"), "looks like")


@pytest.mark.parametrize("scale, unit", [(1e-3, "looks like kN"), (70.0 / STANCE_PEAK_N, "looks like a mass in kg"), (10.0, "looks like mN")])
def test_a_stance_load_in_kn_kg_or_ten_times_too_large_is_warned(scale, unit):
    """The ideal stance (peak 4.08 kN) scaled to read 4.08 (kN), 70 (a body mass in kg) or 40.8 kN."""
    assert said(load_scene("ideal-stance", {"load.force_scale": scale}), unit)
    assert not said(load_scene("ideal-stance"), "the load peaks at")


def test_a_static_verification_load_is_taken_as_written():
    """hemisphere-convergence presses with 1 N on purpose (a single static load): no unit warning."""
    assert not said(load_scene("hemisphere-convergence"), "the load peaks at")


def test_a_load_pulling_the_mobile_body_away_names_swapped_bodies_as_the_likely_cause():
    """The standing load reversed (333 N down, away from the tibia) pulls the talus off: warned
    before the solve refuses it, with the likely causes; pressing it up says nothing."""
    assert said(load_scene("ideal-standing", {"load.force_scale": -1.0}), "the bodies look swapped")
    assert not said(load_scene("ideal-standing"), "look swapped")


def test_a_warning_repeated_at_every_time_point_is_said_once_with_their_count_and_range():
    """Plates pressed past the spring length at three time points (d = 2.5, 3.0, 3.2 mm on 2 mm
    springs): one line naming the 3 time points, k = 0-2, and the range of spring counts."""
    e_conf = 10.35 * (1 - 0.42) / ((1 + 0.42) * (1 - 2 * 0.42))
    forces = [[0.0, 0.0, d * e_conf * 400.0 / 2.0] for d in (2.5, 3.0, 3.2)]
    scene = make_scene(grid_plate(20, 20, 8), plane(lambda x, y: 2.0), forces, time_s=[0.0, 1.0, 2.0],
                       fixed_dofs=("tx", "ty", "rx", "ry", "rz"), allow_bone_overlap=True)  # kept, warned: refused otherwise
    result = run(scene, "dem")
    overstrained = [w for w in result.warnings if "compressed past their length" in w]
    assert overstrained == ["at 3 time points (k = 0-2, t = 0-2 s): 128 springs compressed past their length "
                            "(strain >= 100 %): the spring bed is outside its range"]


def test_merging_keeps_single_and_different_warnings_apart():
    from edem.plausibility import merge_repeated

    lines = ["time point 4 (t = 0.4 s): a 1 mm", "b", "time point 5 (t = 0.5 s): a 3 mm", "b", "c 1", "c 2"]
    assert merge_repeated(lines) == ["at 2 time points (k = 4-5, t = 0.4-0.5 s): a 1-3 mm", "b (2 times)", "c 1", "c 2"]
    assert merge_repeated(["time point 1 (t = 0.1 s): x"]) == ["time point 1 (t = 0.1 s): x"]


def test_edem_solve_issues_every_warning_as_an_edem_warning():
    """The Python API says what `edem run` prints: the scene's and the run's warnings."""
    scene = load_scene("ideal-standing", {"cartilage.youngs_modulus_mpa": 1.035e7})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = edem.solve(scene, method="dem")
    issued = [str(w.message) for w in caught if issubclass(w.category, edem.EdemWarning)]
    assert issued == list(scene.warnings) + result.warnings and any("looks like Pa" in w for w in issued)


def test_max_step_s_splits_the_load_steps_and_the_kinematics_follow():
    """The ideal stance cut to 3 points: steps of 1 s and 0.5 s split into 0.25 s, the given times
    kept, the force and the inline angles (one per given time) interpolated linearly between them."""
    overrides = {"load.time_s": [0.0, 1.0, 1.5], "load.force_n": [[0.0, 0.0, 100.0], [0.0, 0.0, 500.0], [0.0, 0.0, 300.0]],
                 "load.max_step_s": 0.25, "kinematics.angle_deg": [0.0, 4.0, 2.0]}
    scene = load_scene("ideal-stance", overrides)
    np.testing.assert_allclose(scene.load.time_s, [0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5])
    np.testing.assert_allclose(scene.load.force_n[:, 2], [100, 200, 300, 400, 500, 400, 300])
    np.testing.assert_allclose(np.degrees(scene.kinematics.angle_rad), [0, 1, 2, 3, 4, 3, 2])
    with pytest.raises(InputError, match="time points") as info:
        load_scene("ideal-stance", {**overrides, "load.max_step_s": 1e-9})
    assert info.value.key == "load.max_step_s"


def test_every_load_key_is_documented_in_the_readme_scene_section():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text[text.index("## Scene files"):text.index("## Result directory")]
    missing = [key for key in LOAD_KEYS if not re.search(rf"\b{key}\b", section)]
    assert not missing, f"[load] keys not in README.md#scene-files: {missing}"


# --------------------------------------------------------------------------- OpenSim scenes


@pytest.fixture(scope="module")
def model_dir(tmp_path_factory) -> Path:
    pytest.importorskip("opensim")
    from opensim_fixtures import build_model, write_motion

    folder = tmp_path_factory.mktemp("osim")
    build_model(folder)
    write_motion(folder / "walk.mot", [0.0, 0.5, 1.0], [0.0, 4.0, 8.0], [0.0, 0.0005, 0.001])
    return folder


def opensim_scene(folder: Path, load: str, motion: str = "walk.mot", model: str = "two_body_ankle.osim") -> Path:
    path = folder / "plausible.toml"
    path.write_text(f"""[opensim]
model = "{model}"
mobile_body = "talus"
fixed_body = "tibia"
motion = "{motion}"
[cartilage]
youngs_modulus_mpa = 10.35
poissons_ratio = 0.42
max_spring_length_mm = 3.5
[load]
{load}
[constraints]
fixed_dofs = ["tz", "rx", "ry", "rz"]
""", encoding="utf-8")
    return path


@pytest.mark.opensim
def test_load_bodies_contradicting_the_opensim_section_are_refused_naming_the_key(model_dir):
    """[load] mobile_body = "tibia", fixed_body = "talus" under [opensim] mobile_body = "talus": exit
    2 naming load.mobile_body and saying the bodies look swapped (it ran with the load reversed)."""
    from edem.cli import main

    names = ["time"] + [f"ankle_on_talus_in_tibia_{q}{c}" for q in "fmp" for c in "xyz"]
    rows = ["\t".join(f"{v:g}" for v in [t, 0.0, -300.0, 0.0, 0.0, 0.0, 0.0, 0.0, -0.4, 0.0]) for t in (0.0, 0.5, 1.0)]
    (model_dir / "jr.sto").write_text("\n".join(["Joint Reaction Loads", "inDegrees=no", "endheader", "\t".join(names), *rows]) + "\n")
    keys = 'file = "jr.sto"\naxes = "same"\n'
    with pytest.raises(InputError, match="look swapped") as info:
        load_scene(opensim_scene(model_dir, keys + 'mobile_body = "tibia"\nfixed_body = "talus"'))
    assert info.value.key == "load.mobile_body"
    assert main(["run", str(opensim_scene(model_dir, keys + 'mobile_body = "talus"\nfixed_body = "tibia"')), "--out", str(model_dir / "out")]) == 0


@pytest.mark.opensim
def test_a_motion_in_degrees_marked_radians_is_refused_with_the_hint(model_dir):
    """The walk's ankle angles in degrees (to 17.9, as gait2392's) under inDegrees=no: beyond a
    full turn and the coordinate's range (+-10 rad, OpenSim's default): exit 2 saying they look
    like degrees, not an interpenetration of the placed meshes."""
    from opensim_fixtures import write_motion

    motion = write_motion(model_dir / "deg.mot", [0.0, 0.5, 1.0], [0.0, 8.0, 17.9], [0.0, 0.0, 0.0])
    motion.write_text(motion.read_text().replace("inDegrees=yes", "inDegrees=no"))
    load = 'time_s = [0.0, 0.5, 1.0]\nforce_n = [[0.0, 300.0, 0.0], [0.0, 300.0, 0.0], [0.0, 300.0, 0.0]]'
    with pytest.raises(InputError, match=r"'ankle_angle' reaches 17.9 rad .*look like degrees") as info:
        load_scene(opensim_scene(model_dir, load, motion="deg.mot"))
    assert info.value.key == "opensim.motion" and "inDegrees=yes" in info.value.expected


def test_a_kinematics_file_in_degrees_marked_radians_names_degrees(tmp_path):
    """[kinematics] file with 17.9 under inDegrees=no (1026 deg): refused, saying it looks like degrees."""
    (tmp_path / "ik.mot").write_text("Coordinates\ninDegrees=no\nendheader\ntime\tankle_angle_r\n0\t0\n1\t17.9\n")
    scene = tmp_path / "s.toml"
    scene.write_text("""[geometry]
builtin = "ideal_ankle"
[cartilage]
youngs_modulus_mpa = 10.35
poissons_ratio = 0.42
[load]
time_s = [0.0, 1.0]
force_n = [[0.0, 0.0, 300.0], [0.0, 0.0, 300.0]]
[kinematics]
file = "ik.mot"
angle_column = "ankle_angle_r"
axis_point_mm = [0.0, 0.0, -20.0]
axis_direction = [-1.0, 0.0, 0.0]
""", encoding="utf-8")
    with pytest.raises(InputError, match="look like degrees") as info:
        load_scene(scene)
    assert "inDegrees=yes" in info.value.expected


@pytest.mark.opensim
def test_opensim_does_not_print_missing_meshes_of_bodies_the_scene_does_not_use(model_dir, tmp_path, capfd):
    """A mesh on ground whose file is absent (as gait2392's 16 meshes that were not copied): OpenSim
    printed "Couldn't find file" for it on every load; the scene uses only talus and tibia."""
    import shutil

    from edem.opensim_model import import_opensim

    osim = import_opensim()
    shutil.copytree(model_dir, tmp_path, dirs_exist_ok=True)
    model = osim.Model(str(tmp_path / "two_body_ankle.osim"))
    model.getGround().attachGeometry(osim.Mesh("treadmill.vtp"))
    model.finalizeConnections()
    model.printToXML(str(tmp_path / "with_treadmill.osim"))
    capfd.readouterr()
    load = 'time_s = [0.0, 0.5, 1.0]\nforce_n = [[0.0, 300.0, 0.0], [0.0, 300.0, 0.0], [0.0, 300.0, 0.0]]'
    load_scene(opensim_scene(tmp_path, load, model="with_treadmill.osim"))
    out, err = capfd.readouterr()
    assert "treadmill.vtp" not in out + err


def test_edem_converges_at_first_order_as_max_step_s_halves():
    """EDEM is first order in the load step (docs/method.md#what-edem-must-satisfy): a stance cut to
    one jump (20 N -> 4 kN, -3 -> 17 deg) ends 0.67 mm off; split by max_step_s = 0.05, 0.025,
    0.0125 s the final pose's successive differences fall by at least 1.5x per halving (first
    order: 2x; 1.86-1.91 measured, the pre-asymptotic range), i.e. the answer converges."""
    jump = {"load.time_s": [0.0, 0.5], "load.force_n": [[0.0, 0.0, 20.0], [150.0, -50.0, 4000.0]], "kinematics.angle_deg": [-3.0, 17.0]}
    final = [run(load_scene("ideal-stance", {**jump, "load.max_step_s": step}), "edem").steps[-1].displacement_mm
             for step in (0.05, 0.025, 0.0125)]
    first, second = np.linalg.norm(final[1] - final[0]), np.linalg.norm(final[2] - final[1])
    assert first > 1.5 * second > 0.0
