"""The real pairs as an analyst runs them: the log and the HTML report in QGIS's words (no
command-line flags, no library warnings), progress moving through registration, and a reliable
run's summary logged as information, not as a warning."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import pytest
from qgis.core import QgsProcessingFeedback


class RecordingFeedback(QgsProcessingFeedback):
    def __init__(self) -> None:
        super().__init__()
        self.progress: list[float] = []
        self.infos: list[str] = []
        self.warnings: list[str] = []
        self.progressChanged.connect(self.progress.append)

    def pushInfo(self, info: str) -> None:  # noqa: N802 - Qt API
        self.infos.append(info)
        super().pushInfo(info)

    def pushWarning(self, warning: str) -> None:  # noqa: N802 - Qt API
        self.warnings.append(warning)
        super().pushWarning(warning)


def run_pair(run_alg, real_dir: Path, out: Path, before: str, after: str):
    feedback = RecordingFeedback()
    params = {
        "BEFORE": str(real_dir / before),
        "AFTER": str(real_dir / after),
        "DIFFERENCE": str(out / "difference.tif"),
        "REPORT": str(out / "report.html"),
    }
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        results = run_alg("estimatevolumechange", params, feedback=feedback)
    return results, feedback, [str(w.message) for w in caught]


@pytest.fixture(scope="module")
def autzen(run_alg_session, real_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("autzen")
    return run_pair(run_alg_session, real_dir, out, "autzen_bmx_2010.las", "autzen_bmx_2023.las")


@pytest.fixture(scope="module")
def tommy(run_alg_session, real_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("tommy")
    return run_pair(run_alg_session, real_dir, out, "tommy_thompson_park_2015.laz", "tommy_thompson_park_2023.laz")


def visible_text(page: str) -> str:
    return re.sub(r"<[^>]+>", " ", page.split("</style>", 1)[1])


@pytest.mark.parametrize("pair", ["autzen", "tommy"])
def test_log_and_report_name_parameters_not_flags(pair, request):
    results, feedback, caught = request.getfixturevalue(pair)
    lines = feedback.infos + feedback.warnings
    assert not [line for line in lines if re.search(r"(^|[\s(])--[a-z]", line)], lines
    assert not [line for line in lines if "RANSAC" in line], lines
    volumes = [line for line in lines if line.startswith("Volumes (m³)")]
    assert len(volumes) == 1 and not re.search(r"-0\.0\b", volumes[0]), volumes
    assert not [w for w in caught if "Covariance" in w], caught  # scipy's fit warning: noise
    text = visible_text(Path(results["REPORT"]).read_text(encoding="utf-8"))
    assert not re.search(r"(^|[\s(])--[a-z]", text), re.findall(r".{60}--[a-z].{30}", text)
    assert "automatic m" not in text and re.search(r"Zones \(polygons\)\s+none", text)


def test_autzen_precise_run_is_explained_in_parameter_words(autzen):
    results, feedback, _ = autzen
    registration = [line for line in feedback.infos if line.startswith(("Coarse", "Fine"))]
    assert registration and all("'Georeferencing of the surveys' (GEOREFERENCING)" in r for r in registration)
    assert results["VERDICT"] == "use with caution"
    assert results["QUALITY_MESSAGES"] in feedback.warnings  # a caution is a warning


def test_tommy_thompson_progress_moves_through_registration(tommy):
    results, feedback, _ = tommy
    steps = feedback.progress
    start = next(i for i, line in enumerate(feedback.infos) if line.startswith("Registering"))
    assert start >= 0 and steps == sorted(steps)
    assert len({round(p) for p in steps if 15 < p < 50}) >= 3, steps  # ICP levels move the bar
    assert results["VERDICT"] == "reliable" and not feedback.warnings  # the summary is no warning
    assert results["NET_VOLUME"] - results["NET_UNCERTAINTY"] > 0  # a significant gain
