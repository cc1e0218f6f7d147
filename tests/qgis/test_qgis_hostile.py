"""Hostile inputs through the QGIS algorithms: one clear message, never a hang."""

from __future__ import annotations

import pytest
from qgis.core import QgsProcessingException


@pytest.mark.parametrize("text", ["[1, 2]", '{"type": "FeatureCollection", "features": "x"}'])
def test_a_malformed_vpc_is_one_message(run_alg, scene_dir, tmp_path, alarm, text):
    bad = tmp_path / "bad.vpc"
    bad.write_text(text)
    params = {"BEFORE": str(bad), "AFTER": str(scene_dir / "after.las"), "DIFFERENCE": str(tmp_path / "d.tif")}
    with pytest.raises(QgsProcessingException, match="bad.vpc"):
        run_alg("estimatevolumechange", params)


@pytest.mark.parametrize(
    ("scheduler", "expect"), [("tcp://", "no host"), ("tls://a:1", "TLS"), ("tcp://localhost:99999", "port")]
)
def test_a_bad_scheduler_names_the_parameter(run_alg, scene_dir, tmp_path, alarm, scheduler, expect):
    params = {
        "BEFORE": str(scene_dir / "before.las"),
        "AFTER": str(scene_dir / "after.las"),
        "DIFFERENCE": str(tmp_path / "d.tif"),
        "SCHEDULER": scheduler,
    }
    with pytest.raises(QgsProcessingException, match=rf"\(SCHEDULER\): .*{expect}"):
        run_alg("estimatevolumechange", params)
    assert not (tmp_path / "d.tif").exists()
