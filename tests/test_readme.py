"""The README's examples run as written (house style: examples in the docs are run by the tests)."""

import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def test_python_examples_in_readme_run():
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), flags=re.S)
    assert blocks
    for block in blocks:
        exec(compile(block, str(README), "exec"), {})


def test_ci_runs_the_readme_test_command():
    """CI calls exactly the README's test command."""
    ci = (README.parent / ".ci" / "run").read_text(encoding="utf-8")
    assert "make test" in README.read_text(encoding="utf-8")
    assert [line for line in ci.splitlines() if line and not line.startswith(("#", "set ", "cd "))] == ["make test"]


def test_opensim_section_runs_as_written(tmp_path):
    """The README's [opensim] scene, on the two-body model tests/opensim_fixtures.py builds with a
    JointReaction of the talus in the tibia frame: `edem run` exits 0 and the contact carries the
    load at every time point (force balance with no ligaments: sum p A n = applied force on the
    free DOFs)."""
    import numpy as np
    import pytest

    pytest.importorskip("opensim")
    from opensim_fixtures import build_model, write_motion

    from edem.cli import main
    from edem.resultdir import read_timeseries_csv

    text = README.read_text(encoding="utf-8")
    section = text[text.index("## From an OpenSim model"):]
    scene = re.search(r"```toml\n(.*?)```", section, flags=re.S).group(1)
    build_model(tmp_path)
    time = [0.0, 0.5, 1.0]
    write_motion(tmp_path / "walk.mot", time, [0.0, 4.0, 8.0], [0.0, 0.0005, 0.001])
    prefix = "ankle_on_talus_in_tibia"
    names = ["time"] + [f"{prefix}_{q}{c}" for q in "fmp" for c in "xyz"]
    # the tibia holding the talus down with 400 N, as OpenSim writes a talus pressed up into it
    rows = ["\t".join(f"{v:g}" for v in [t, 0.0, -400.0, 0.0, 0.0, 0.0, 0.0, 0.0, -0.4, 0.0]) for t in time]
    (tmp_path / "ankle_reaction.sto").write_text(
        "\n".join(["Joint Reaction Loads", "version=1", "nRows=3", f"nColumns={len(names)}", "inDegrees=no", "endheader", "\t".join(names), *rows]) + "\n"
    )
    (tmp_path / "ankle.toml").write_text(scene, encoding="utf-8")
    assert main(["run", str(tmp_path / "ankle.toml"), "--out", str(tmp_path / "out")]) == 0
    series = read_timeseries_csv(tmp_path / "out" / "timeseries.csv")
    applied = np.column_stack([series[f"force_{c}_n"] for c in "xyz"])
    contact = np.column_stack([series[f"contact_force_{c}_n"] for c in "xyz"])
    # tz is fixed (the constraint carries that component); x and y: the solver's 1e-10 balance
    np.testing.assert_allclose(contact[:, :2], applied[:, :2], atol=1e-6)
    assert np.all(series["contact_area_mm2"] > 0)
