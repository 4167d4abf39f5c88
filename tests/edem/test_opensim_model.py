"""Scenes from an OpenSim model (edem.opensim_model): meshes found and placed as OpenSim does,
the relative pose of the two bodies from every coordinate of the motion, loads in the model's
frames, and `edem run` end to end."""

from __future__ import annotations

import csv
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("opensim")
from opensim_fixtures import (  # noqa: E402
    JOINT_CENTRE_IN_TIBIA_M,
    PLATE_ABOVE_DOME_M,
    build_model,
    tibia_pose_in_talus_mm,
    write_motion,
)

from edem.cli import main  # noqa: E402
from geometries.errors import InputError  # noqa: E402
from edem.scene import load_scene  # noqa: E402

pytestmark = pytest.mark.opensim
TIME_S = [0.0, 0.5, 1.0]
ANGLE_DEG = [0.0, 4.0, 8.0]
SLIDE_M = [0.0, 0.0005, 0.001]


@pytest.fixture(scope="module")
def model_dir(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("osim")
    build_model(folder)
    write_motion(folder / "walk.mot", TIME_S, ANGLE_DEG, SLIDE_M)
    return folder


def write_scene(folder: Path, load: str, extra: str = "", name: str = "ankle.toml") -> Path:
    path = folder / name
    path.write_text(
        f"""[scene]
name = "two-body-ankle"
[opensim]
model = "two_body_ankle.osim"
mobile_body = "talus"
fixed_body = "tibia"
motion = "walk.mot"
{extra}
[cartilage]
youngs_modulus_mpa = 10.35
poissons_ratio = 0.42
max_spring_length_mm = 3.5
[load]
{load}
[constraints]
fixed_dofs = ["tz", "rx", "ry"]
""",
        encoding="utf-8",
    )
    return path


INLINE_LOAD = 'time_s = [0.0, 0.5, 1.0]\nforce_n = [[0.0, 300.0, 0.0], [0.0, 300.0, 0.0], [0.0, 300.0, 0.0]]'


def test_fixed_body_pose_comes_from_every_coordinate_of_the_motion(model_dir):
    """F in M's frame at each time point equals the inverse of the CustomJoint's transform at the
    motion's angle (deg -> rad) AND slide (m -> mm), to round-off."""
    scene = load_scene(write_scene(model_dir, INLINE_LOAD))
    for k, (angle, slide) in enumerate(zip(ANGLE_DEG, SLIDE_M)):
        rotation, translation = tibia_pose_in_talus_mm(angle, slide)
        placement = scene.fixed_placement(k)
        np.testing.assert_allclose(placement.rotation, rotation, atol=1e-12)
        np.testing.assert_allclose(placement.points(np.zeros((1, 3)))[0], translation, atol=1e-9)
    assert np.allclose(scene.kinematics.coordinates["ankle_angle"], np.radians(ANGLE_DEG))
    assert not any("not in the motion" in w for w in scene.warnings)  # both coordinates are given


def test_meshes_are_found_scaled_and_placed_in_their_body_frames(model_dir):
    """The talus dome in the talus frame (top at y = 0), the plate in the tibia frame on its offset
    frame (y = -400 + 1.5 mm) at twice the file's size (scale_factors 2): 40 x 40 mm."""
    scene = load_scene(write_scene(model_dir, INLINE_LOAD))
    assert scene.mobile.vertices_mm[:, 1].max() == pytest.approx(0.0, abs=1e-9)
    plate = scene.fixed.vertices_mm
    np.testing.assert_allclose(plate[:, 1], 1000.0 * (JOINT_CENTRE_IN_TIBIA_M[1] + PLATE_ABOVE_DOME_M), atol=1e-9)
    assert np.ptp(plate[:, 0]) == pytest.approx(40.0, rel=1e-9) and np.ptp(plate[:, 2]) == pytest.approx(40.0, rel=1e-9)
    # placed at the first time point, the plate faces the dome 1.5 mm above its top
    placed = scene.fixed_placement(0).points(plate)
    np.testing.assert_allclose(placed[:, 1], 1.5, atol=1e-9)
    assert np.all(scene.fixed_placement(0).vectors(scene.fixed.unit_normals)[:, 1] < -0.99)


def test_missing_mesh_file_names_where_it_was_looked_for(model_dir, tmp_path):
    (tmp_path / "two_body_ankle.osim").write_text((model_dir / "two_body_ankle.osim").read_text())
    (tmp_path / "walk.mot").write_text((model_dir / "walk.mot").read_text())
    with pytest.raises(InputError, match=r"talus_dome.stl.*not found.*Geometry"):
        load_scene(write_scene(tmp_path, INLINE_LOAD))
    scene = load_scene(write_scene(tmp_path, INLINE_LOAD, extra=f'geometry_path = ["{model_dir / "Geometry"}"]'))
    assert scene.mobile.n_triangles > 0


def test_missing_opensim_package_says_how_to_install_it(model_dir, monkeypatch):
    monkeypatch.setitem(sys.modules, "opensim", None)
    with pytest.raises(InputError, match=r"opensim.*pip install -e '\.\[opensim\]'"):
        load_scene(write_scene(model_dir, INLINE_LOAD))


def write_reaction(path: Path, prefix: str, force_n, moment_nm, point_m) -> Path:
    names = ["time"] + [f"{prefix}_{q}{c}" for q in "fmp" for c in "xyz"]
    lines = ["Joint Reaction Loads", "version=1", "nRows=3", f"nColumns={len(names)}", "inDegrees=no", "endheader", "\t".join(names)]
    for t in TIME_S:
        lines.append("\t".join(f"{v:.10f}" for v in [t, *force_n, *moment_nm, *point_m]))
    path.write_text("\n".join(lines) + "\n")
    return path


def test_jointreaction_in_ground_equals_the_same_load_in_the_welded_tibia_frame(model_dir):
    """The tibia is welded to ground at the identity: a reaction expressed in ground and the same
    numbers expressed in the tibia (frame 'fixed') give the same load about G at every time point
    (turned into M's frame through the model's pose, moment moved from the joint centre to G)."""
    f, m, p = [10.0, 300.0, -5.0], [1.0, 0.5, 2.0], list(JOINT_CENTRE_IN_TIBIA_M)
    write_reaction(model_dir / "jr_ground.sto", "ankle_on_talus_in_ground", f, m, p)
    write_reaction(model_dir / "jr_tibia.sto", "ankle_on_talus_in_tibia", f, m, p)
    keys = 'axes = "same"\nmobile_body = "talus"\nfixed_body = "tibia"'
    ground = load_scene(write_scene(model_dir, f'file = "jr_ground.sto"\n{keys}', name="g.toml"))
    tibia = load_scene(write_scene(model_dir, f'file = "jr_tibia.sto"\n{keys}', name="t.toml"))
    np.testing.assert_allclose(ground.applied_loads(), tibia.applied_loads(), rtol=1e-9, atol=1e-9)
    # at the last time point the tibia turned by -8 deg in the talus frame: the force with it
    rotation, _ = tibia_pose_in_talus_mm(ANGLE_DEG[-1], SLIDE_M[-1])
    np.testing.assert_allclose(tibia.applied_loads()[-1, :3], -rotation @ f, rtol=1e-12)  # on the talus: negated


def test_opensim_model_and_motion_drive_edem_run_end_to_end(model_dir, capsys):
    """`edem run` on the model scene: exit 0, every time point balances its load, the dome touches
    the turned and slid plate at every time point; and the joint's coordinates are written out."""
    out = model_dir / "out"
    assert main(["run", str(write_scene(model_dir, INLINE_LOAD)), "--out", str(out)]) == 0, capsys.readouterr().err
    with open(out / "timeseries.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 3
    for row in rows:
        assert float(row["force_residual_n"]) <= 1e-8 * 300.0  # the solver's round-off tolerance
        assert float(row["contact_area_mm2"]) > 0


@pytest.mark.parametrize("original, damaged, message", [
    ("<scale_factors>2 2 2</scale_factors>", "<scale_factors>nan 2 2</scale_factors>", r"body 'tibia': its mesh 'tibia_plate.stl'.*not finite"),
    ("<translation>0 -0.40000000000000002 0</translation>", "<translation>0 nan 0</translation>", r"at time point 0 .*places 'tibia' in 'talus'"),
    ("<axis>0 0 1</axis>", "<axis>0 1e300 1</axis>", r"at time point 1 \(t = 0.5 s\).*not a rotation"),  # at 0 the angle is 0
])
def test_a_model_placing_a_body_at_non_finite_coordinates_is_refused(model_dir, tmp_path, original, damaged, message):
    """A NaN scale factor or frame offset, or a joint axis of (0, 1e300, 1), in the .osim (a fuzz
    found them: they reached a KD-tree as a ValueError, the orientation as an IndexError, the
    ray caster as a non-orthogonal rotation) is exit 2 naming the model file."""
    shutil.copytree(model_dir, tmp_path, dirs_exist_ok=True)
    model = tmp_path / "two_body_ankle.osim"
    text = model.read_text(encoding="utf-8")
    assert original in text  # the fixture writes it
    model.write_text(text.replace(original, damaged, 1), encoding="utf-8")
    with pytest.raises(InputError, match=message) as err:
        load_scene(write_scene(tmp_path, INLINE_LOAD))
    assert str(model) in str(err.value)


def test_a_model_opensim_cannot_assemble_is_refused(model_dir, tmp_path):
    """A joint frame whose parent socket names no frame (an .osim fuzz found it) made
    Model.initSystem raise a RuntimeError from C++: exit 2 naming the model file."""
    shutil.copytree(model_dir, tmp_path, dirs_exist_ok=True)
    model = tmp_path / "two_body_ankle.osim"
    text = model.read_text(encoding="utf-8")
    assert "<socket_parent>/bodyset/tibia</socket_parent>" in text
    model.write_text(text.replace("<socket_parent>/bodyset/tibia</socket_parent>", "<socket_parent>/bodyset/fibula</socket_parent>", 1), encoding="utf-8")
    with pytest.raises(InputError, match="OpenSim cannot assemble the model") as err:
        load_scene(write_scene(tmp_path, INLINE_LOAD))
    assert str(model) in str(err.value)


def _mutated(text: str, rng) -> str:
    """One damage of a text file: cut short, a number made hostile, a line dropped, a word renamed."""
    import re

    kind = rng.randrange(4)
    if kind == 0:
        return text[: rng.randrange(len(text) + 1)]
    if kind == 1:
        numbers = list(re.finditer(r"-?\d+(\.\d+)?(e-?\d+)?", text))
        m = rng.choice(numbers)
        return text[: m.start()] + rng.choice(["nan", "inf", "-1", "1e300", "0", "abc", "99999999999"]) + text[m.end():]
    if kind == 2:
        lines = text.splitlines()
        del lines[rng.randrange(len(lines))]
        return "\n".join(lines)
    m = rng.choice(list(re.finditer(r"[A-Za-z_]{3,}", text)))
    return text[: m.start()] + rng.choice(["x", "talus", "tibia", "ground", ""]) + text[m.end():]


N_MODEL_FUZZ_CASES = 120  # about 20 ms each: most damage is refused while the model loads


def test_damaged_models_and_motions_exit_0_or_2_without_traceback(model_dir, tmp_path):
    """Seeded fuzz of the .osim and the motion (an .osim fuzz of 450 cases found the three classes
    of refusal above): every run ends with status 0, or 2 with a message."""
    import contextlib
    import io
    import random

    rng = random.Random(13)
    failures = []
    for n in range(N_MODEL_FUZZ_CASES):
        folder = tmp_path / f"case{n:02d}"
        shutil.copytree(model_dir, folder)
        victim = folder / rng.choice(["two_body_ankle.osim", "walk.mot"])
        victim.write_text(_mutated(victim.read_text(encoding="utf-8"), rng), encoding="utf-8")
        err = io.StringIO()
        try:
            with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
                status = main(["run", str(write_scene(folder, INLINE_LOAD)), "--out", str(folder / "out")])
        except BaseException as exc:  # noqa: BLE001 - any escape is what the test looks for
            failures.append(f"case {n} ({victim.name}): {type(exc).__name__}: {str(exc)[:200]}")
            continue
        if status not in (0, 2) or (status == 2 and not err.getvalue().strip()):
            failures.append(f"case {n} ({victim.name}): status {status}, stderr {err.getvalue()[:200]!r}")
    assert not failures, "\n".join(failures)
