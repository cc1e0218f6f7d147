"""The HTML report the estimate writes: run date, version, inputs and every parameter,
registration as rotation and shift, change-area volumes, significance and quality in words, no
internal keys."""

from __future__ import annotations

import html
import json
import re
from pathlib import Path

import pytest

from soilvolume.options import command_fields
from soilvolume.reporting.report import WHEN_SET

INTERNAL = ("nugget_m2", "psill_m2", "lod_m", "sigma_m", "net_compared_area", "volume_m3", "_m3", "transform")


@pytest.fixture(scope="module")
def page(estimate_run) -> str:
    return Path(estimate_run["REPORT"]).read_text(encoding="utf-8")


def visible_text(page: str) -> str:
    body = page.split("</style>", 1)[1]
    return re.sub(r"<[^>]+>", " ", body)


def test_run_date_version_and_parameters(page, estimate_run):
    text = visible_text(page)
    assert re.search(r"Run on \d{4}-\d\d-\d\d \d\d:\d\d", text) and "with soilvolume " in text
    report = json.loads(Path(estimate_run["REPORT_JSON"]).read_text())
    assert Path(report["inputs"]["before"]["path"]).name in text
    for field in command_fields("estimate"):  # every option the estimate took (those only given when set: if set)
        if field.name in WHEN_SET and report["options"].get(field.name) is None:
            continue
        assert field.metadata["label"] in text, field.name


def test_registration_as_rotation_and_shift(page):
    assert "rotation (°)" in page and "shift (m)" in page
    assert "c1" not in visible_text(page)  # no 4x4 matrix in absolute coordinates


def test_volumes_significance_and_no_internal_keys(page, estimate_run):
    text = visible_text(page)
    assert "areas of significant change (headline)" in text and "every compared cell" in text
    assert estimate_run["SIGNIFICANCE"] in html.unescape(text)
    for key in INTERNAL:
        assert key not in text, key


def test_quality_verdict_and_messages(estimate_run):
    from soilvolume.core.types import GridSpec
    from soilvolume.reporting.html import render_html

    report = json.loads(Path(estimate_run["REPORT_JSON"]).read_text())
    report["quality"] = {
        "verdict": "use with caution",
        "trusted": True,
        "messages": ["Only 40 % of the after cloud fits the before surface."],
    }
    page = render_html(report, {}, GridSpec(xmin=0.0, ymax=10.0, cell=1.0, rows=10, cols=10), "2026-01-02 03:04 UTC")
    assert "Quality: <b>use with caution</b>" in page and "Only 40 % of the after cloud" in page
    assert "Run on 2026-01-02 03:04 UTC" in page
