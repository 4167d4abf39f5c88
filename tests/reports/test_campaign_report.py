"""The campaign HTML report (reports/html.py) and the pressure maps (reports/maps.py).

Invariants: every link and image of the page resolves relative to it; rendered in headless
Chromium every <img> decodes (naturalWidth > 0); the contact outline is the set of edges with
exactly one triangle in contact; a pressure map is a non-blank picture of the requested size.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from verification.campaigns import Campaign, Figure, get_campaign
from reports.html import write_campaign_report
from verification.runner import run_campaign

CHECK_IMAGES_JS = """<script>
window.addEventListener('load', () => {
  const imgs = Array.from(document.images);
  const ok = imgs.filter(i => i.complete && i.naturalWidth > 0).length;
  const mark = document.createElement('div');
  mark.id = 'img-check';
  mark.textContent = 'LOADED ' + ok + ' OF ' + imgs.length;
  document.body.appendChild(mark);
});
</script>"""


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> Path:
    """A small campaign with every kind of figure: a sweep, a time series and pressure maps."""
    quick = get_campaign("quick")
    names = ("hemisphere-L1", "hemisphere-L2", "log-law-n8", "pull-apart", "ideal-standing-edem-vs-dem")
    campaign = Campaign(
        "report-test",
        "figures of every kind",
        tuple(quick.case(n) for n in names),
        (
            Figure("hemi", "hemisphere sweep", "sweep", ("hemisphere-L1", "hemisphere-L2"), x="subdivisions", y=("thickness_mean_mm", "thickness_sd_mm"), logy=(False, True), exact={"thickness_mean_mm": 0.5}),
            Figure("ramp", "log-law time series", "timeseries", ("log-law-n8",), column="disp_z_mm"),
        ),
    )
    out = tmp_path_factory.mktemp("campaign")
    summary = run_campaign(campaign, out, jobs=1, report=write_campaign_report)
    return Path(summary["report"])


def test_report_lists_cases_versions_and_resolving_links(report):
    text = report.read_text(encoding="utf-8")
    for name in ("hemisphere-L1", "log-law-n8", "pull-apart", "ideal-standing-edem-vs-dem"):
        assert name in text
    for package in ("python", "numpy", "scipy", "vtk", "pyvista"):
        assert f"<th>{package}</th>" in text
    assert "no equilibrium" in text  # the refusal message of pull-apart
    assert "not drawn" not in text  # every figure was drawn
    targets = re.findall(r'(?:href|src)="([^"#:]+)"', text)
    assert sum(t.endswith("pressure.pvd") for t in targets) >= 5
    for target in targets:
        assert (report.parent / target).exists(), target
    images = re.findall(r'<img src="([^"]+)"', text)
    assert {"figures/hemi.png", "figures/ramp.png", "figures/ideal-standing-edem-vs-dem-maps.png", "figures/wall-times.png"} <= set(images)


def test_report_images_render_in_headless_chromium(report, tmp_path):
    chromium = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
    if chromium is None:
        pytest.skip("chromium is not installed (Debian: apt-get install -y chromium); the link checks above still ran")
    page = report.parent / "report-check.html"
    page.write_text(report.read_text(encoding="utf-8").replace("</body>", CHECK_IMAGES_JS + "</body>"), encoding="utf-8")
    n_images = len(re.findall(r"<img ", page.read_text(encoding="utf-8")))
    run = subprocess.run(
        [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--virtual-time-budget=10000", "--dump-dom", page.as_uri()],
        capture_output=True, text=True, timeout=120,
    )
    found = re.search(r'<div id="img-check">LOADED (\d+) OF (\d+)</div>', run.stdout)
    assert found, run.stderr[-2000:]
    assert int(found.group(2)) == n_images >= 4
    assert int(found.group(1)) == n_images  # every image decoded
    shot = tmp_path / "report.png"
    subprocess.run([chromium, "--headless", "--no-sandbox", "--disable-gpu", f"--screenshot={shot}", "--window-size=1200,1600", report.as_uri()], capture_output=True, timeout=120)
    assert shot.is_file() and shot.stat().st_size > 10_000


def test_report_redraws_nothing_when_rerun_unchanged(report):
    figures = sorted((report.parent / "figures").glob("*.png"))
    before = {p.name: p.stat().st_mtime_ns for p in figures}
    from reports.html import write_campaign_report
    import json

    summary = json.loads((report.parent / "metrics.json").read_text(encoding="utf-8"))
    write_campaign_report(summary, report.parent)
    assert {p.name: p.stat().st_mtime_ns for p in figures} == before


def test_contact_outline_edges_of_a_hand_example():
    """Two squares side by side (4 triangles), only the left square in contact: its outline is the
    4 edges of that square (the diagonal is shared by two contact triangles)."""
    from reports.maps import contact_outline_edges

    # 0 - 1 - 2
    # | / | / |
    # 3 - 4 - 5
    triangles = np.array([[3, 4, 1], [3, 1, 0], [4, 5, 2], [4, 2, 1]])
    edges = contact_outline_edges(triangles, np.array([True, True, False, False]))
    assert {tuple(e) for e in edges.tolist()} == {(0, 1), (0, 3), (3, 4), (1, 4)}
    assert contact_outline_edges(triangles, np.zeros(4, bool)).size == 0


def test_pressure_maps_picture_of_a_run_against_its_closed_form(tmp_path):
    from matplotlib.image import imread

    from edem.results import write_results
    from edem.solver import run
    from reports.maps import render_pressure_maps
    from verification.campaigns import SCENES_DIR
    from verification.closed_forms import solve_closed_form, write_closed_form_results

    scene, solution = solve_closed_form("cylinder-plane", str(SCENES_DIR / "cylinder-plane.toml"))
    a = write_results(run(scene, "dem"), tmp_path / "dem")
    b = write_closed_form_results(scene, solution, tmp_path / "cf")
    png = render_pressure_maps(a, b, tmp_path / "maps.png", window_size=(900, 300))
    image = imread(png)
    assert image.shape[:2] == (300, 900)
    assert image[..., :3].std() > 0.05  # not a blank picture
    third = image.shape[1] // 3
    for k in range(3):
        panel = image[:, k * third : (k + 1) * third, :3]
        assert (np.abs(panel - 1.0).sum(axis=2) > 0.1).mean() > 0.05  # each panel draws something
