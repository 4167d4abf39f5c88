"""Measured thickness on a real knee (Lenhart 2015, OpenSim JAM): the tibial cartilage with its
subchondral bone against the femoral subchondral bone with a uniform 2 mm layer (the femoral
cartilage mesh is not public in a usable size). Runs only where the public data sit at
``../shared/data/lenhart2015-knee`` beside the repository (CI); skipped otherwise.

Invariants: the contact area grows with the load, and it does not depend on the ray window h_max
once the window sees where the articular surfaces meet (the gap law's contact is set by the
geometry and the local thickness, not by h_max; before measured thickness the threshold law's
area on this knee was set by h_max alone).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from edem.scene import load_scene
from edem.solver import solve

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "lenhart2015-knee"
LOADS_N = (500.0, 1000.0, 2000.0)


def knee_scene(data: Path, tmp_path: Path, coupling: str) -> Path:
    """The scene file: the tibia (M) pressed up its long axis (y) into the femur (F) at the
    model's neutral pose, translations across the plateau and rotations fixed; JAM's tf_contact
    material (E 10 MPa, nu 0.45)."""
    path = tmp_path / "knee.toml"
    forces = ", ".join(f"[0, {f:g}, 0]" for f in LOADS_N)
    path.write_text(f"""
[geometry]
mobile = "{data / 'lenhart2015-R-tibia-cartilage.stl'}"
mobile_bone = "{data / 'lenhart2015-R-tibia-subchondral-bone.stl'}"
fixed = "{data / 'lenhart2015-R-femur-subchondral-bone-tf20.stl'}"
units = "m"

[cartilage]
youngs_modulus_mpa = 10.0
poissons_ratio = 0.45
law = "gap"
max_spring_length_mm = 8.0
fixed_thickness_mm = 2.0
coupling = "{coupling}"

[load]
time_s = [0, 1, 2]
force_n = [{forces}]

[constraints]
fixed_dofs = ["tx", "tz", "rx", "ry", "rz"]
""")
    return path


@pytest.mark.skipif(not DATA.is_dir(), reason=f"public knee data not found at {DATA}")
@pytest.mark.parametrize("coupling", ["none", "thin-layer"])
def test_knee_contact_area_grows_with_load_and_does_not_depend_on_h_max(tmp_path, coupling):
    path = knee_scene(DATA, tmp_path, coupling)
    runs = {h: solve(load_scene(path, {"cartilage.max_spring_length_mm": h}), method="dem") for h in (8.0, 10.0)}
    area = {h: np.array([s.contact_area_mm2 for s in run.steps]) for h, run in runs.items()}
    peak = {h: np.array([s.peak_pressure_mpa for s in run.steps]) for h, run in runs.items()}
    # A contact of curved surfaces on an elastic foundation grows its area like F^(1/2) (a
    # paraboloidal gap: 41 % per doubling of the load; measured 40-46 %). 10 % per doubling is far
    # below that and far above one spring's area (the largest is under 1 % of the smallest area).
    assert np.all(area[8.0][1:] > 1.10 * area[8.0][:-1]), area[8.0]
    # h_max only decides which far surfaces the rays see: the area is a sum of spring areas, so
    # any change moves it by at least one spring's area. Nothing may change: below one spring.
    one_spring = float(runs[8.0].scene.spring_area_mm2.max())
    np.testing.assert_allclose(area[10.0], area[8.0], rtol=0.0, atol=0.5 * one_spring)
    # the same springs carry the same forces: the peak to round-off (1e-9: the solves' KKT tolerance is far below)
    np.testing.assert_allclose(peak[10.0], peak[8.0], rtol=1e-9)
    # the bone lies under most of the cartilage (misses: the rims beyond the bone mesh), JAM's 3 mm
    # lumped layer is within the measured range
    report = runs[8.0].summary()["cartilage_thickness"]
    assert report["mobile"]["source"] == "bone" and 0.5 < report["mobile"]["measured_area_share"] < 1.0
    assert report["mobile"]["min_mm"] < 3.0 < report["mobile"]["max_mm"]
