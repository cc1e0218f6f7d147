"""The real pairs as an analyst runs them: the log and the HTML report in QGIS's words (no
command-line flags, no library warnings), progress moving through registration, and a reliable
run's summary logged as information, not as a warning."""

from __future__ import annotations

import json
import math
import re
import warnings
from pathlib import Path

import pytest
from qgis.core import (
    QgsLayerTreeModel,
    QgsProcessingContext,
    QgsProcessingFeedback,
    QgsProcessingOutputLayerDefinition,
    QgsProject,
    QgsRasterLayer,
    QgsVectorLayer,
)

from .recording import RecordingFeedback
from .test_qgis_outputs import legend_range


def run_pair(run_alg, real_dir: Path, out: Path, before: str, after: str, **extra):
    feedback = RecordingFeedback()
    params = {
        "BEFORE": str(real_dir / before),
        "AFTER": str(real_dir / after),
        "DIFFERENCE": str(out / "difference.tif"),
        "REPORT": str(out / "report.html"),
        **extra,
    }
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        results = run_alg("estimatevolumechange", params, feedback=feedback)
    return results, feedback, [str(w.message) for w in caught]


@pytest.fixture(scope="module")
def autzen(run_alg_session, real_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("autzen")
    zones = polygons(out / "zones.geojson", {"mound": (194482, 259235, 194498, 259252), "west": WEST})
    stable = polygons(out / "stable.geojson", {"east": (194500, 259222, 194508, 259264)})
    extra = {"ZONES": str(zones), "STABLE_MASK": str(stable), "ZONE_VOLUMES": str(out / "zones.gpkg")}
    return run_pair(run_alg_session, real_dir, out, "autzen_bmx_2010.las", "autzen_bmx_2023.las", **extra)


WEST = (194472, 259222, 194480, 259264)


def polygons(path: Path, boxes: dict[str, tuple[float, float, float, float]]) -> Path:
    """A GeoJSON of named rectangles in Autzen's horizontal CRS (EPSG:2991, metres)."""
    features = [
        {
            "type": "Feature",
            "properties": {"name": name},
            "geometry": {"type": "Polygon", "coordinates": [[[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]]},
        }
        for name, (x0, y0, x1, y1) in boxes.items()
    ]
    crs = {"type": "name", "properties": {"name": "urn:ogc:def:crs:EPSG::2991"}}
    path.write_text(json.dumps({"type": "FeatureCollection", "crs": crs, "features": features}))
    return path


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
    for message in filter(None, results["QUALITY_MESSAGES"].split("\n")):
        logged = [line for line in lines if message.lower() in line.lower() and not line.startswith("Results:")]
        assert len(logged) == 1, logged  # once (processing.run's "Results:" line aside)
    assert not [w for w in caught if "Covariance" in w], caught  # scipy's fit warning: noise
    text = visible_text(Path(results["REPORT"]).read_text(encoding="utf-8"))
    assert not re.search(r"(^|[\s(])--[a-z]", text), re.findall(r".{60}--[a-z].{30}", text)
    assert "automatic m" not in text
    if pair == "tommy":
        assert re.search(r"Zones \(polygons\)\s+none", text)


def test_autzen_zones_and_stable_mask(autzen):
    """The per-zone table on the real pair: one row per polygon with cut, fill, net and its ±;
    zero volumes are plain 0 (never -0.0); no deprecation noise from the plugin's fields."""
    results, _, caught = autzen
    layer = QgsVectorLayer(results["ZONE_VOLUMES"], "zones", "ogr")
    rows = {f["name"]: f for f in layer.getFeatures()}
    assert set(rows) == {"mound", "west"} and layer.crs().authid() == "EPSG:2991"
    mound = rows["mound"]
    assert mound["fill_m3"] > 20 and mound["net_m3"] == pytest.approx(mound["fill_m3"] - mound["cut_m3"])
    assert all(row["net_pm_m3"] > 0 for row in rows.values())
    for key in ("NET_VOLUME", "CUT_VOLUME", "FILL_VOLUME"):
        assert math.copysign(1.0, results[key]) == 1.0, key
    assert not [w for w in caught if "QgsField constructor is deprecated" in w], caught
    assert "not significant" in results["QUALITY_MESSAGES"] and " m3" not in results["QUALITY_MESSAGES"]


def test_autzen_precise_run_is_explained_in_parameter_words(autzen):
    results, feedback, _ = autzen
    registration = [line for line in feedback.infos if line.startswith(("Coarse", "Fine"))]
    assert registration and all("'Georeferencing of the surveys' (GEOREFERENCING)" in r for r in registration)
    assert results["VERDICT"] == "use with caution"
    assert "Comparing the surfaces (no vertical bias correction)" in feedback.infos  # a precise run
    assert not [line for line in feedback.infos if line.startswith("Estimating the vertical bias")]
    assert set(results["QUALITY_MESSAGES"].split("\n")) <= set(feedback.warnings)  # cautions are warnings


def test_tommy_thompson_progress_moves_through_registration(tommy):
    results, feedback, _ = tommy
    steps = feedback.progress
    start = next(i for i, line in enumerate(feedback.infos) if line.startswith("Registering"))
    assert start >= 0 and steps == sorted(steps)
    assert len({round(p) for p in steps if 15 < p < 50}) >= 3, steps  # ICP levels move the bar
    # the 2023 survey reaches 120 m east of the 2015 one: 7 % of its footprint is not compared
    assert results["VERDICT"] == "not reliable"
    # and a 359 m2 basin inside the works the 2015 survey has no point in (water): its range said too
    assert len(feedback.warnings) == 2, feedback.warnings
    assert any("The before survey does not cover" in w for w in feedback.warnings)
    assert any("no point at all in the before survey" in w for w in feedback.warnings)
    # a gain over the compared area, whose interval also holds what the 7 % no before data covers could hide
    # (up to ~15,600 m3 of the rise the 2023 survey shows past the 2015 edge): the site's net is not known
    assert results["NET_VOLUME"] > 0 and results["NET_UNCERTAINTY"] > 15_000


def test_autzen_layers_as_loaded(run_alg, real_dir, tmp_path):
    """Autzen's outputs as Processing loads them: the difference on top; every legend shows the
    styled range, which follows the data (DEMs in metres, 128-134 m; the zero correction of a
    precise run a narrow ±0.1 m, not the style file's ±1 m); nodata set; no vertical CRS."""
    project = QgsProject.instance()
    context = QgsProcessingContext()
    context.setProject(project)
    keys = ("DIFFERENCE", "DEM_BEFORE", "DEM_AFTER", "PLANE_OFFSET")
    loaded = {k: QgsProcessingOutputLayerDefinition(str(tmp_path / f"{k}.tif"), project) for k in keys}
    params = {"BEFORE": str(real_dir / "autzen_bmx_2010.las"), "AFTER": str(real_dir / "autzen_bmx_2023.las")}
    run_alg("estimatevolumechange", {**params, **loaded}, context=context)
    details = context.layersToLoadOnCompletion()
    assert max(details.values(), key=lambda d: d.layerSortKey).name.startswith("Difference")
    model = QgsLayerTreeModel(project.layerTreeRoot())
    ranges = {}
    try:
        for path, d in details.items():
            layer = QgsRasterLayer(path, d.name)
            project.addMapLayer(layer)
            d.postProcessor().postProcessLayer(layer, context, QgsProcessingFeedback())
            renderer = layer.renderer()
            name = re.sub(r", run \d+\)$", ")", d.name)  # a later run of the pair in this session
            ranges[name] = (renderer.classificationMin(), renderer.classificationMax())
            assert legend_range(model, layer) == pytest.approx(ranges[name]), d.name
            assert layer.dataProvider().sourceNoDataValue(1) == -9999
            assert not layer.verticalCrs().isValid() and "ftUS" not in layer.crs().toWkt()
    finally:
        project.removeAllMapLayers()
    for name in ("DEM before (autzen_bmx_2010)", "DEM after (registered) (autzen_bmx_2023)"):
        assert 128 < ranges[name][0] < ranges[name][1] < 134, ranges
    assert ranges["Vertical correction (autzen_bmx_2023)"] == pytest.approx((-0.1, 0.1)), ranges
    (group,) = {d.groupName for d in details.values()}  # one group for the run, named after it
    assert group.startswith("Soil volume: autzen_bmx_2010 → autzen_bmx_2023 (run "), group
