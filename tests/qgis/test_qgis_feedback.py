"""Progress, engine log lines, cancellation, and output styling."""

from __future__ import annotations

import pytest
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
