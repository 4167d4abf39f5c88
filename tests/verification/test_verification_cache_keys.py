"""Campaign cache keys follow the source a case uses, not every file of the project."""

from __future__ import annotations

import shutil

import pytest

import verification.runner as runner
from verification import sources
from verification.campaign_model import COMPARISON_METRICS, Case

DEM_CASE = Case("plates", "DEM vs the closed form", "flat-plates.toml", ("dem", "closed-form:flat-plates"), COMPARISON_METRICS)
FE_CASE = Case("plates-fe", "DEM vs the FE slab", "flat-plates.toml", ("dem", "fe-slab"), COMPARISON_METRICS)


@pytest.fixture
def source_copy(tmp_path, monkeypatch):
    """A copy of the five packages the keys are computed from; returns a key function and an editor."""
    for package in sources.PACKAGES:
        shutil.copytree(sources.ROOT / package, tmp_path / package, ignore=shutil.ignore_patterns("__pycache__"))
    monkeypatch.setattr(runner, "SOURCE_ROOT", tmp_path)

    def edit(relative: str) -> None:
        with open(tmp_path / relative, "a", encoding="utf-8") as f:
            f.write("\n# an edit\n")
        sources.source_digest.cache_clear()
        sources.closure_digest.cache_clear()

    return edit


def test_editing_other_campaigns_or_reports_keeps_cached_cases_valid(source_copy):
    keys = (runner.case_key(DEM_CASE), runner.case_key(FE_CASE))
    for module in ("verification/campaigns/stance.py", "verification/campaigns/__init__.py", "verification/campaign_model.py",
                   "reports/html.py", "reports/maps.py", "verification/analyses.py", "edem/cli.py"):
        source_copy(module)
        assert (runner.case_key(DEM_CASE), runner.case_key(FE_CASE)) == keys, module


def test_editing_the_fe_reference_rekeys_fe_cases_only(source_copy):
    dem, fe = runner.case_key(DEM_CASE), runner.case_key(FE_CASE)
    source_copy("fem_reference/models.py")
    assert runner.case_key(DEM_CASE) == dem and runner.case_key(FE_CASE) != fe


@pytest.mark.parametrize("module", ["edem/laws.py", "geometries/builders.py", "verification/closed_forms.py", "verification/metrics.py",
                                    "edem/resultdir.py", "verification/runner.py"])
def test_editing_code_a_case_uses_rekeys_it(source_copy, module):
    key = runner.case_key(DEM_CASE)
    source_copy(module)
    assert runner.case_key(DEM_CASE) != key
