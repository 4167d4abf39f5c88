"""`edem compare` headlines the peak-load instant (not the last time point) and warns when the two
runs are not like for like (different ligaments or constraints, ligaments against the FE)."""

from __future__ import annotations

import pytest

from edem.cli import main
from verification.campaigns import SCENES_DIR

PLATES = str(SCENES_DIR / "flat-plates.toml")
SERIES = ["--set", "load.time_s=[0.0, 1.0, 2.0]", "--set", "load.force_n=[[0.0, 0.0, 100.0], [0.0, 0.0, 400.0], [0.0, 0.0, 200.0]]"]


def test_compare_headlines_the_peak_load_instant(tmp_path, capsys):
    assert main(["run", PLATES, "--method", "dem", "--out", str(tmp_path / "a"), *SERIES]) == 0
    assert main(["run", PLATES, "--method", "edem", "--out", str(tmp_path / "b"), *SERIES]) == 0
    capsys.readouterr()
    assert main(["compare", str(tmp_path / "a"), str(tmp_path / "b"), "--out", str(tmp_path / "cmp")]) == 0
    out = capsys.readouterr().out
    assert "peak-load instant t = 1 s (|F| = 400 N)" in out
    # p = F/A on the 20 x 20 mm plates at 400 N: 1 MPa, the headline row's value
    for label in ("regularised peak", "raw peak"):  # a uniform field: its mean over any disc is itself
        peak = next(line for line in out.splitlines() if line.startswith(label))
        assert float(peak.split()[3]) == pytest.approx(1.0, rel=1e-12)
    assert "warning" not in out


def test_compare_warns_when_constraints_or_ligaments_differ(tmp_path, capsys):
    from edem.scene import resolve_scene_path

    text = resolve_scene_path("ideal-standing").read_text(encoding="utf-8")
    bare = tmp_path / "ideal-standing-no-ligaments.toml"
    bare.write_text(text[: text.index("[[ligaments]]")], encoding="utf-8")
    assert main(["run", "ideal-standing", "--out", str(tmp_path / "a")]) == 0
    assert main(["run", str(bare), "--out", str(tmp_path / "b"), "--set", 'constraints.fixed_dofs=["tx", "ty", "rx", "ry", "rz"]']) == 0
    capsys.readouterr()
    assert main(["compare", str(tmp_path / "a"), str(tmp_path / "b"), "--out", str(tmp_path / "cmp")]) == 0
    out = capsys.readouterr().out
    assert "warning: the ligaments differ" in out and "ATiTL" in out
    assert "warning: the constraints differ" in out and "'ty'" in out
