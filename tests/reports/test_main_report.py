"""The main job's report (`make demo` = `edem verify quick`) opens with the ankle answer: the trust
summary comes first, then verdict counts that match the cases, as a browser shows the page.

The whole quick campaign runs once here (a few minutes on 2 cores; its FE cases are reported
unavailable without dolfinx, and the trust summary then says so)."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from collections import Counter
from pathlib import Path

import pytest

from verification.verdicts import CASE_VERDICTS

READ_PAGE_JS = """<script>
window.addEventListener('load', () => {
  const out = {
    firstHeading: document.querySelector('h2') ? document.querySelector('h2').textContent : '',
    trustBeforeCounts: !!document.getElementById('trust-summary') && !!document.getElementById('verdict-counts') &&
      (document.getElementById('trust-summary').compareDocumentPosition(document.getElementById('verdict-counts')) & Node.DOCUMENT_POSITION_FOLLOWING) > 0,
    sentences: Array.from(document.querySelectorAll('#trust-summary li')).map(li => li.textContent),
    counts: Object.fromEntries(Array.from(document.querySelectorAll('td.verdict-count')).map(td => [td.dataset.verdict, Number(td.textContent)])),
    rows: Array.from(document.querySelectorAll('td.status')).map(td => td.textContent),
  };
  const mark = document.createElement('pre');
  mark.id = 'page-check';
  mark.textContent = JSON.stringify(out);
  document.body.appendChild(mark);
});
</script>"""


@pytest.fixture(scope="module")
def main_report(tmp_path_factory) -> tuple[Path, dict]:
    from reports.html import write_campaign_report
    from verification.campaigns import get_campaign
    from verification.runner import run_campaign

    out = tmp_path_factory.mktemp("quick")
    summary = run_campaign(get_campaign("quick"), out, jobs=2, report=write_campaign_report)
    return Path(summary["report"]), summary


def test_trust_summary_opens_the_page_and_counts_match_the_cases(main_report):
    report, summary = main_report
    text = report.read_text(encoding="utf-8")
    trust, counts, cases = text.index('id="trust-summary"'), text.index('id="verdict-counts"'), text.index("<h2>Cases</h2>")
    assert trust < counts < cases
    assert text.index("<h2>") > trust - 200 and "passed" not in re.sub(r"<[^>]+>", " ", text).split()
    expected = Counter(r["status"] for r in summary["cases"])
    for verdict in CASE_VERDICTS:
        assert f'data-verdict="{verdict}">{expected.get(verdict, 0)}<' in text


def test_main_report_in_headless_chromium(main_report, tmp_path):
    chromium = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
    if chromium is None:
        pytest.skip("chromium is not installed (scripts/ensure-chromium.sh installs Debian's package)")
    report, summary = main_report
    page = report.parent / "report-read.html"
    page.write_text(report.read_text(encoding="utf-8").replace("</body>", READ_PAGE_JS + "</body>"), encoding="utf-8")
    run = subprocess.run([chromium, "--headless", "--no-sandbox", "--disable-gpu", "--virtual-time-budget=10000", "--dump-dom", page.as_uri()],
                         capture_output=True, text=True, timeout=180)
    found = re.search(r'<pre id="page-check">(.*?)</pre>', run.stdout, re.S)
    assert found, run.stderr[-2000:]
    seen = json.loads(found.group(1).replace("&quot;", '"').replace("&amp;", "&").replace("&lt;", "<").replace("&gt;", ">"))
    assert seen["firstHeading"].startswith("Can I trust it for my ankle")
    assert seen["trustBeforeCounts"]
    assert seen["sentences"] and ("FE" in seen["sentences"][0] or "FE" in " ".join(seen["sentences"]))
    expected = Counter(r["status"] for r in summary["cases"])
    assert seen["counts"] == {v: expected.get(v, 0) for v in CASE_VERDICTS}
    assert Counter(seen["rows"]) == expected  # the cases table shows the same verdicts
    assert sum(seen["counts"].values()) == len(summary["cases"])
