""" "Volume change over a series of surveys" through processing.run on the seeded 4-epoch site
(soilvolume.scenes.series), the engine run as a subprocess in its own environment."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
from qgis.core import QgsProcessingException, QgsRasterLayer


@pytest.fixture(scope="module")
def series_site(tmp_path_factory):
    from soilvolume.scenes.series import write_series

    return write_series(tmp_path_factory.mktemp("series_scene"), seed=0)


@pytest.fixture(scope="module")
def series_run(qgis_processing, plugin_package, run_alg_session, series_site, tmp_path_factory):
    paths, _ = series_site
    out = tmp_path_factory.mktemp("series_out")
    params = {
        "EPOCHS": [str(p) for p in paths],
        "DATES": ",,2026-03-17,",
        "OUTPUT_FOLDER": str(out / "folder"),
        "LEDGER": str(out / "elsewhere" / "ledger.csv"),
        "REPORT": str(out / "elsewhere" / "series.html"),
    }
    return run_alg_session("volumeseries", params)


def test_periods_and_cumulative(series_run, series_site):
    _, truth = series_site
    periods = json.loads(series_run["PERIODS"])
    assert [(p["from"], p["to"]) for p in periods] == [(0, 1), (1, 2), (2, 3)]
    for p, t in zip(periods, truth["periods"], strict=True):
        assert abs(p["volume_m3"]["net"] - t["net"]) <= 0.02 * (t["cut"] + t["fill"])
        assert p["volume_m3"]["cut"] == pytest.approx(t["cut"], rel=0.03)
        assert p["volume_m3"]["fill"] == pytest.approx(t["fill"], rel=0.03)
    assert sum(p["volume_m3"]["net"] for p in periods) == pytest.approx(series_run["CUMULATIVE_NET"], abs=1e-9)
    assert series_run["CUMULATIVE_FILL"] == pytest.approx(truth["cumulative"]["fill"], rel=0.03)
    assert series_run["CUMULATIVE_NET_UNCERTAINTY"] > 0
    assert periods[1]["dates"] == ["2026-03-09", "2026-03-17"]  # the given date overrides the header's


def test_outputs_delivered(series_run):
    folder = Path(series_run["OUTPUT_FOLDER"])
    names = {p.name for p in folder.iterdir()}
    assert {f"dem_epoch{k}.tif" for k in range(4)} <= names
    assert {"difference_0_1.tif", "difference_1_2.tif", "difference_2_3.tif", "cumulative_0_3.tif"} <= names
    assert {"ledger.csv", "report.json", "report.html"} <= names
    layer = QgsRasterLayer(str(folder / "cumulative_0_3.tif"), "cumulative")
    try:
        assert layer.isValid() and layer.crs().authid() == "EPSG:32654"
    finally:
        del layer
    rows = list(csv.DictReader(Path(series_run["LEDGER"]).open()))
    assert [r["period"] for r in rows] == ["1", "2", "3", "cumulative"]
    assert float(rows[-1]["net_m3"]) == pytest.approx(series_run["CUMULATIVE_NET"], abs=1e-3)
    assert "<polyline" in Path(series_run["REPORT"]).read_text()
    assert not any(".partial" in n for n in names)


def test_one_cloud_is_refused_before_the_engine_runs(provider, run_alg, series_site, tmp_path):
    """One survey: the parameter check says a series needs two (was QGIS's generic "Incorrect
    parameter value for Point clouds in time order"), and so does the run; nothing written."""
    from qgis.core import QgsApplication, QgsProcessingContext

    paths, _ = series_site
    alg = QgsApplication.processingRegistry().algorithmById("soilvolume:volumeseries")
    values = {"EPOCHS": [str(paths[0])], "OUTPUT_FOLDER": str(tmp_path / "out")}
    ok, message = alg.checkParameterValues(values, QgsProcessingContext())
    assert not ok and "needs at least two surveys (1 given" in message, message
    with pytest.raises(QgsProcessingException, match="at least two surveys"):
        run_alg("volumeseries", values)
    assert not (tmp_path / "out").exists()
