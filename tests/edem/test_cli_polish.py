"""Command-line details a researcher meets first: `edem plot` needs no --out and shows a single time
point, `edem scenes` prints whole descriptions."""

from __future__ import annotations

import tomllib

from edem.cli import main
from edem.scene import builtin_scene_names, resolve_scene_path


def test_plot_defaults_its_output_and_marks_a_single_time_point(tmp_path, capsys):
    assert main(["run", "ideal-standing", "--out", str(tmp_path / "standing")]) == 0
    capsys.readouterr()
    assert main(["plot", str(tmp_path / "standing"), "--column", "peak_pressure_mpa"]) == 0
    png = tmp_path / "standing-peak_pressure_mpa.png"  # beside the sealed result directory, not in it
    assert capsys.readouterr().out.strip() == str(png) and png.stat().st_size > 5_000

    import matplotlib

    matplotlib.use("Agg")
    from unittest import mock

    import matplotlib.axes

    calls = []
    original = matplotlib.axes.Axes.plot

    def spy(self, *args, **kwargs):
        calls.append((args, kwargs))
        return original(self, *args, **kwargs)

    with mock.patch.object(matplotlib.axes.Axes, "plot", spy):
        assert main(["plot", str(tmp_path / "standing"), "--out", str(tmp_path / "one.png")]) == 0
    (x, y, fmt), kwargs = calls[0]
    assert len(x) == 1 and fmt == "o" and "one time point" in kwargs["label"]  # a marker, not an invisible line


def test_scenes_prints_every_description_whole(capsys):
    assert main(["scenes"]) == 0
    printed = " ".join(capsys.readouterr().out.split())
    for name in builtin_scene_names():
        description = " ".join(tomllib.loads(resolve_scene_path(name).read_text(encoding="utf-8"))["scene"]["description"].split())
        assert f"{name} {description}" in printed


def test_fe_progress_defaults_to_a_terminal_and_waits_there(monkeypatch):
    """`edem fe` progress inside a solve: --no-progress never, --progress from the first
    iteration, the default only when stderr is a terminal and only once a solve has run
    TERMINAL_QUIET_S (the many short solves of a small model stay silent)."""
    import io
    import sys

    from edem.cli import _fe_solve_progress
    from fem_reference.progress import TERMINAL_QUIET_S

    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    monkeypatch.setattr(sys, "stderr", io.StringIO())
    assert _fe_solve_progress(None, None) is None and _fe_solve_progress(False, None) is None
    forced = _fe_solve_progress(True, None)
    assert forced.quiet_s == 0.0
    forced.write("a line")
    assert sys.stderr.getvalue() == "a line\n"
    monkeypatch.setattr(sys, "stderr", Terminal())
    assert _fe_solve_progress(None, None).quiet_s == TERMINAL_QUIET_S
    assert _fe_solve_progress(False, None) is None
