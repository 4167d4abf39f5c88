"""Campaigns under concurrency, interrupts and damage: one writer per directory, workers that die
with their parent, Ctrl-C without a traceback keeping every finished case, kills at random
points never leaving a half case that a rerun would use, damaged cached cases recomputed, and
library versions in the cache key."""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import verification.runner as runner
from edem.atomic_dirs import manifest_problems
from verification.campaign_model import Campaign
from verification.campaign_safety import campaign_lock
from verification.campaigns import get_campaign
from verification.runner import case_key, run_campaign

ROOT = Path(__file__).resolve().parents[2]
#: cases of `edem-analytic` (closed forms; quick opens with slow FE cases) run by the subprocess campaigns: ~2-4 s with 2 workers, long enough to be
#: interrupted half-way, short enough for CI.
N_CASES = 12

SCRIPT = """
import sys

if __name__ == "__main__":  # the spawned workers import this file too
    import verification.campaigns as campaigns
    from edem.cli import main
    from verification.campaign_model import Campaign

    quick = campaigns.get_campaign("edem-analytic")
    which = sys.argv[2]  # the number of first cases, or case names separated by commas
    cases = quick.cases[: int(which)] if which.isdigit() else tuple(quick.case(name) for name in which.split(","))
    tiny = Campaign("tiny", "cases of edem-analytic", tuple(cases))
    campaigns.get_campaign = lambda name: tiny
    sys.exit(main(["verify", "tiny", "--out", sys.argv[1], "--jobs", "2"]))
"""


def tiny(n: int = N_CASES) -> Campaign:
    return Campaign("tiny", "the first cases of edem-analytic", tuple(get_campaign("edem-analytic").cases[:n]))


def start(tmp_path: Path, out: Path, n: int | str = N_CASES) -> subprocess.Popen:
    script = tmp_path / "campaign.py"
    script.write_text(SCRIPT)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    # a session of its own: signals go to the campaign and its workers as a terminal sends them
    return subprocess.Popen([sys.executable, str(script), str(out), str(n)], env=env, cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                            preexec_fn=default_sigint)


def default_sigint() -> None:
    """A shell without job control starts its background jobs with SIGINT ignored, and Python then
    keeps it ignored: give the child the terminal's default so the Ctrl-C tests hold however the
    suite itself was started."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def finished_cases(out: Path) -> list[str]:
    return sorted(p.parent.name for p in (out / "cases").glob("*/metrics.json")) if (out / "cases").is_dir() else []


def wait_for(predicate, timeout_s: float = 120.0) -> None:
    end = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > end:
            raise AssertionError("timed out")
        time.sleep(0.05)


def alive_in_group(pgid: int) -> list[int]:
    """Live (not zombie) processes of a process group, from /proc."""
    pids = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[2]) == pgid and fields[0] != "Z":
                pids.append(int(entry.name))
    return pids


def metrics_by_case(out: Path) -> dict[str, dict]:
    data = json.loads((out / "metrics.json").read_text())
    return {row["name"]: row["metrics"] for row in data["cases"]}


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> dict[str, dict]:
    """The tiny campaign run once, undisturbed, in this process."""
    out = tmp_path_factory.mktemp("reference") / "out"
    summary = run_campaign(tiny(), out, jobs=1)
    assert summary["counts"]["verified"] == N_CASES
    return metrics_by_case(out)


def test_a_second_campaign_on_a_locked_directory_is_refused(tmp_path):
    out = tmp_path / "out"
    with campaign_lock(out):
        done = start(tmp_path, out, 2)
        _, err = done.communicate(timeout=120)
    assert done.returncode == 2, err
    assert f"another campaign (pid {os.getpid()}) is writing this directory" in err and "Traceback" not in err
    assert finished_cases(out) == []


def test_two_campaigns_at_once_one_runs_the_other_is_refused(tmp_path, reference):
    out = tmp_path / "out"
    first, second = start(tmp_path, out), start(tmp_path, out)
    results = [p.communicate(timeout=300) + (p.returncode,) for p in (first, second)]
    codes = sorted(r[2] for r in results)
    assert codes == [0, 2], results
    refused = next(r for r in results if r[2] == 2)
    assert "another campaign" in refused[1] and "Traceback" not in refused[1]
    assert metrics_by_case(out) == reference


def test_ctrl_c_stops_cleanly_and_keeps_every_finished_case(tmp_path, reference):
    out = tmp_path / "out"
    campaign = start(tmp_path, out)
    wait_for(lambda: len(finished_cases(out)) >= 2 or campaign.poll() is not None)
    os.killpg(campaign.pid, signal.SIGINT)  # as Ctrl-C in a terminal: the campaign and its workers
    _, err = campaign.communicate(timeout=60)
    kept = finished_cases(out)
    assert campaign.returncode == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err and "interrupted:" in err, err
    assert 2 <= len(kept) < N_CASES  # interrupted half-way, the finished cases kept
    wait_for(lambda: alive_in_group(campaign.pid) == [], 10.0)  # no worker left behind
    summary = run_campaign(tiny(), out, jobs=1)
    assert summary["cached"] >= len(kept) and summary["counts"]["verified"] == N_CASES
    assert metrics_by_case(out) == reference


def test_killing_the_campaign_kills_its_workers(tmp_path):
    """Two slow cases (~2-3 s each), one per worker: once both have started, SIGKILL the main
    process only. The workers die with it and finish neither case (they used to run on)."""
    out = tmp_path / "out"
    slow = ("log-law-n128", "hemisphere-L6")
    campaign = start(tmp_path, out, ",".join(slow))
    wait_for(lambda: all((out / "cases" / name).is_dir() for name in slow) or campaign.poll() is not None)
    assert campaign.poll() is None
    os.kill(campaign.pid, signal.SIGKILL)
    campaign.communicate(timeout=30)
    # the kernel kills the workers with their parent (PR_SET_PDEATHSIG): a few ms, 10 s is generous
    wait_for(lambda: alive_in_group(campaign.pid) == [], 10.0)
    time.sleep(3.0)  # longer than either case: a surviving worker would have written it by now
    assert finished_cases(out) == []


def test_kills_at_random_points_never_leave_a_case_a_rerun_would_use(tmp_path, reference):
    """SIGKILL of the whole campaign at random instants (seeded), then a rerun: the rerun's
    metrics equal the undisturbed run's exactly (the solver is deterministic), so no half-written
    case was taken from the cache."""
    rng = random.Random(14)
    out = tmp_path / "out"
    for _ in range(3):
        campaign = start(tmp_path, out)
        time.sleep(rng.uniform(0.5, 4.0))
        os.killpg(campaign.pid, signal.SIGKILL)
        campaign.communicate(timeout=30)
        wait_for(lambda: alive_in_group(campaign.pid) == [], 10.0)
        # never partial: every side result directory under its final name verifies (half-written
        # ones exist only as hidden temporary siblings)
        sides = [d for d in (out / "cases").glob("*/[ab]-*") if d.is_dir()] if (out / "cases").is_dir() else []
        assert all(manifest_problems(d) == [] for d in sides), [(d, manifest_problems(d)) for d in sides if manifest_problems(d)]
    summary = run_campaign(tiny(), out, jobs=1)
    assert summary["counts"]["verified"] == N_CASES
    assert metrics_by_case(out) == reference


def test_damaged_cached_cases_are_recomputed(tmp_path):
    """A pressure map deleted from one cached case and timeseries.csv truncated in another: the
    rerun runs those two again (it used to report them passed from the cache)."""
    out = tmp_path / "out"
    campaign = tiny(4)
    first = run_campaign(campaign, out, jobs=1)
    assert first["computed"] == 4
    a, b = (out / "cases" / c.name for c in campaign.cases[:2])
    next(a.glob("a-*/pressure_*.vtp")).unlink()
    series = next(b.glob("a-*/timeseries.csv"))
    series.write_bytes(series.read_bytes()[: series.stat().st_size // 2])
    seen: dict[str, bool] = {}
    second = run_campaign(campaign, out, jobs=1, on_case=lambda name, cached: seen.__setitem__(name, cached))
    assert second["computed"] == 2 and not seen[a.name] and not seen[b.name]
    assert [r["metrics"] for r in second["cases"]] == [r["metrics"] for r in first["cases"]]


def test_library_versions_are_in_the_cache_key(monkeypatch):
    case = tiny(1).cases[0]
    before = case_key(case)
    versions = dict(runner.library_versions())
    monkeypatch.setattr(runner, "library_versions", lambda: {**versions, "numpy": "0.0.1"})
    assert case_key(case) != before


def test_a_full_disk_in_a_side_is_a_crash_run_again_not_a_refusal(tmp_path, monkeypatch):
    import errno

    import edem.atomic_dirs as atomic_dirs

    def full(path, data):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))

    out = tmp_path / "out"
    campaign = tiny(2)
    monkeypatch.setattr(atomic_dirs, "_write_file", full)
    first = run_campaign(campaign, out, jobs=1)
    assert first["counts"]["error"] == 2 and first["exit_status"] == 1
    assert "disk is full" in first["cases"][0]["sides"][0]["message"]
    monkeypatch.undo()
    again = run_campaign(campaign, out, jobs=1)
    assert again["computed"] == 2 and again["counts"]["verified"] == 2


def test_a_full_file_system_ends_the_campaign_with_exit_2_and_no_traceback(tmp_path):
    """A real 96 KiB tmpfs: the campaign's cases and report do not fit."""
    where = tmp_path / "mnt"
    where.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", "size=96k", "tmpfs", str(where)], capture_output=True).returncode:
        pytest.skip("mounting a tmpfs needs root")
    try:
        campaign = start(tmp_path, where / "out")
        _, err = campaign.communicate(timeout=300)
        assert campaign.returncode == 2, err
        assert "Traceback" not in err and ("disk is full" in err or "No space left" in err), err
        sides = [d for d in (where / "out" / "cases").glob("*/[ab]-*") if d.is_dir()]
        assert all(manifest_problems(d) == [] for d in sides)  # what was written is whole
    finally:
        subprocess.run(["umount", str(where)], check=True)
