"""Progress, engine log lines, cancellation, and output styling."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from processes import group_alive
from qgis.core import (
    QgsProcessingException,
    QgsProcessingFeedback,
    QgsRasterLayer,
    QgsSingleBandPseudoColorRenderer,
)

from .recording import RecordingFeedback


def test_progress_and_engine_log(run_alg, scene_dir, tmp_path):
    feedback = RecordingFeedback()
    run_alg(
        "pointcloudtodem",
        {"INPUT": str(scene_dir / "before.las"), "CELL": 2.0, "OUTPUT": str(tmp_path / "dem.tif")},
        feedback=feedback,
    )
    assert feedback.progress and feedback.progress[-1] == pytest.approx(100)
    assert feedback.progress == sorted(feedback.progress)
    assert any("gridding" in line.lower() for line in feedback.infos)  # an engine log line


def test_cancel_writes_nothing(run_alg, scene_dir, tmp_path):
    feedback = QgsProcessingFeedback()
    feedback.cancel()
    with pytest.raises(QgsProcessingException, match="Cancelled"):
        run_alg(
            "pointcloudtodem",
            {"INPUT": str(scene_dir / "before.las"), "OUTPUT": str(tmp_path / "dem.tif")},
            feedback=feedback,
        )
    assert not (tmp_path / "dem.tif").exists()


class CancelAt(RecordingFeedback):
    """Presses Cancel once the progress reaches ``percent``; remembers when."""

    def __init__(self, percent: float) -> None:
        super().__init__()
        self.at: float | None = None
        self.progressChanged.connect(lambda p: self._maybe(p, percent))

    def _maybe(self, progress: float, percent: float) -> None:
        if progress >= percent and self.at is None:
            self.at = time.perf_counter()
            self.cancel()


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc")
def test_cancel_mid_run_stops_within_a_second_and_leaves_nothing(run_alg, scene_dir, tmp_path, monkeypatch):
    """Cancel during the registration: the exception within a second (or half the time the run
    took to reach the registration, when a loaded machine slows everything), the engine and its process
    group gone, no destination written, the run's private folder in Processing's temp removed."""
    from qgis.core import QgsProcessingUtils
    from soilvolume_qgis.plugin import child

    started = []
    real_start = child.start
    monkeypatch.setattr(child, "start", lambda *a, **k: started.append(real_start(*a, **k)) or started[-1])
    temp = Path(QgsProcessingUtils.tempFolder())
    before = set(temp.glob("soilvolume_*"))
    feedback = CancelAt(25.0)
    started_at = time.perf_counter()
    outputs = {key: str(tmp_path / f"{key.lower()}.tif") for key in ("DIFFERENCE", "DEM_BEFORE", "DEM_AFTER")}
    with pytest.raises(QgsProcessingException, match="Cancelled"):
        run_alg(
            "estimatevolumechange",
            {
                "BEFORE": str(scene_dir / "before.las"),
                "AFTER": str(scene_dir / "after.las"),
                "CHANGE_AREAS": str(tmp_path / "areas.gpkg"),
                "REPORT": str(tmp_path / "report.html"),
                **outputs,
            },
            feedback=feedback,
        )
    seconds = time.perf_counter() - feedback.at
    (proc,) = started
    # within a second, or half the time the run took to get there on a loaded machine
    assert seconds < max(1.0, 0.5 * (feedback.at - started_at)), (seconds, feedback.at - started_at)
    assert proc.poll() is not None and group_alive(proc.pid) == []
    assert list(tmp_path.iterdir()) == []
    assert set(temp.glob("soilvolume_*")) == before


@pytest.mark.parametrize(("key", "kind"), [("DIFFERENCE", "difference"), ("DEM_BEFORE", "dem")])
def test_styles(estimate_run, key, kind, plugin_package):
    from soilvolume_qgis.processing import styles

    layer = QgsRasterLayer(estimate_run[key], key)
    try:
        assert styles.apply_style(layer, kind)
        renderer = layer.renderer()
        assert isinstance(renderer, QgsSingleBandPseudoColorRenderer)
        lo, hi = renderer.classificationMin(), renderer.classificationMax()
        if kind == "difference":
            assert lo == pytest.approx(-hi) and hi > 0.5
        else:
            assert 55 < lo < hi < 75  # the scene's ground heights
        items = renderer.shader().rasterShaderFunction().colorRampItemList()
        assert items[0].value == pytest.approx(lo) and items[-1].value == pytest.approx(hi)
    finally:
        del layer
