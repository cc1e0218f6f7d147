"""Only soil counts (issue 19): what is not soil is said per point (classification, colour,
returns) and per blob (objects by their walls), excluded or listed, and carried in the interval.

Small seeded pairs on a site of 80 x 78 m (after survey 40 x 37 m) at about 40 points per m2,
so vehicles are resolved by 0.5 m cells (measured figures in each test's docstring)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import rasterio
from conftest import SITE

from soilvolume.api import estimate
from soilvolume.options import Options
from soilvolume.scenes.synthetic import SceneConfig, write_pair_streaming
from soilvolume.soil import objects, points
from soilvolume.soil.points import OBJECT, OTHER, SOIL, VEGETATION, PointRule, Signals


def _pair(tmp: Path, seed: int, **cfg) -> tuple[Path, Path, dict]:
    b, a, t = write_pair_streaming(seed, SceneConfig(**{**SITE, **cfg}), tmp, "las")
    return b, a, json.loads(Path(t).read_text())


def _run(pair, out: Path, **opts) -> dict:
    return estimate(pair[0], pair[1], out, Options(**opts), overwrite=True).report


@pytest.fixture(scope="module")
def no_change(tmp_path_factory):
    """No soil change; 3 vehicles moved, grass grown on 4 patches, bushes grown; RGB."""
    folder = tmp_path_factory.mktemp("nochange")
    pair = _pair(folder / "data", 41, change="none", signals="rgb", movers=3, patches=4)
    return pair, _run(pair, folder / "auto"), _run(pair, folder / "none", exclude="none")


def test_no_change_with_nuisances_reads_no_change(no_change):
    """Measured: net -4.0 m3 (cut 4.9, fill 0.9) +- 4.6 m3, use with caution; with --exclude none
    +54.4 m3 (cut 44.1, fill 98.6)."""
    _, auto, none = no_change
    v, u = auto["volume_m3"], auto["uncertainty_m3"]
    assert abs(v["net"]) <= 8.0 and v["cut"] <= 10.0 and v["fill"] <= 10.0
    assert abs(v["net"]) <= u["net"]  # the interval holds 0
    assert none["volume_m3"]["fill"] > v["fill"] + 40.0  # what --exclude none restores
    assert auto["quality"]["verdict"] != "reliable"


def test_moved_objects_excluded_and_listed(no_change):
    """Each moved vehicle is a pair of blobs (apparent fill where it is, cut where it was)."""
    pair, auto, none = no_change
    moved = auto["excluded"]["moved_objects"]
    assert moved["count"] == 3 and moved["excluded"]
    assert len(moved["items"]) == 6 and {i["kind"] for i in moved["items"]} == {"fill", "cut"}
    assert all(1.2 <= i["height_m"] <= 2.0 and 4.0 <= i["area_m2"] <= 14.0 for i in moved["items"])
    truth = [o for o in pair[2]["one_epoch_objects"] if o["epoch"] == "after"]
    found = [i for i in moved["items"] if i["kind"] == "fill"]
    for o in truth:  # every vehicle's new place is listed, within 1.5 m
        assert min(np.hypot(i["x"] - o["x"], i["y"] - o["y"]) for i in found) < 1.5
    assert none["excluded"]["moved_objects"]["excluded"] is False  # --exclude none counts them
    assert any("moved object" in m for m in auto["quality"]["messages"])


def test_excluded_raster_and_report(no_change, tmp_path_factory):
    """excluded.tif holds the classes drawn in report.html; vegetation by colour is excluded."""
    _, auto, _ = no_change
    veg = auto["excluded"]["classes"]["vegetation"]
    assert veg["area_m2"] > 30.0 and veg["fill"] > 20.0  # grass and bushes grew: apparent fill left out
    assert "ExG" in auto["excluded"]["rule"]["after"]
    out = Path(auto["inputs"]["after"]["path"]).parents[1] / "auto"
    with rasterio.open(out / "excluded.tif") as ds:
        c = ds.read(1)
        assert ds.dtypes[0] == "uint8" and ds.nodata == 255
    assert (c == 1).sum() * 0.25 > 20 and (c == 4).sum() > 20  # vegetation and moved objects (0.5 m cells)
    assert "What is not soil" in (out / "report.html").read_text()


def test_one_survey_object_left_out_and_listed(tmp_path):
    """A machine parked in the after survey only is no earthworks: left out of the headline by
    default and listed with its volume; ``--objects count`` counts it (the seed paper's pillars
    are such objects). Measured: net +0.0 m3 by default, +13.4 m3 counted, for a 12.6 m3 vehicle."""
    pair = _pair(tmp_path / "data", 42, change="none", signals="rgb", arrivals=1, vegetation=False)
    rep, counted = _run(pair, tmp_path / "r"), _run(pair, tmp_path / "c", objects="count")
    (obj,) = pair[2]["one_epoch_objects"]
    for r, kept in ((rep, False), (counted, True)):
        single = r["excluded"]["single_objects"]
        assert single["count"] == 1 and single["counted"] is kept
        assert single["items"][0]["volume_m3"] == pytest.approx(obj["volume"], rel=0.25)
    assert abs(rep["volume_m3"]["net"]) <= 1.0
    assert counted["volume_m3"]["net"] == pytest.approx(obj["volume"], rel=0.25)
    from soilvolume.reporting.report import nonsoil_lines

    assert any("left out as machines" in m for m in nonsoil_lines(rep))  # listed under the volumes
    assert any("one survey only" in m and "counted" in m for m in nonsoil_lines(counted))
    # a machine's size: it may be a small steep heap, so the interval holds both readings
    for r in (rep, counted):
        assert r["uncertainty"]["unclassified_m3"]["net"] == pytest.approx(obj["volume"], rel=0.25)
    assert rep["uncertainty_m3"]["net"] >= obj["volume"] * 0.75  # the counted reading in the interval
    assert counted["uncertainty_m3"]["net"] >= counted["volume_m3"]["net"]  # 0 (no soil moved) in it


def test_pile_never_excluded(tmp_path):
    """A pile (and piles beside moved machines) is soil whatever the signals: colour does not
    fire on it and its flanks are no walls. Measured: -0.9 % net."""
    pair = _pair(tmp_path / "data", 43, change="pile", signals="rgb", movers=2, site_tone="grey")
    rep = _run(pair, tmp_path / "r")
    assert rep["volume_m3"]["net"] == pytest.approx(pair[2]["net"], rel=0.02)
    assert all(i["height_m"] < 2.5 for i in rep["excluded"]["moved_objects"]["items"])
    assert rep["excluded"]["single_objects"]["count"] == 0


def test_point_rule_classification_colour_returns():
    """The per-point labels: LAS classes by their meaning; ExG on chromatic coordinates with
    green the strongest channel (a yellow machine is not vegetation); early returns of several."""
    rule = PointRule(use_class=True)
    labels = rule.labels(np.array([2, 3, 5, 6, 7, 18, 1, 9], np.uint8), None)
    assert labels.tolist() == [SOIL, VEGETATION, VEGETATION, OBJECT, OTHER, OTHER, OTHER, OTHER]
    rgb = np.array([[128, 102, 78], [118, 116, 110], [88, 112, 62], [205, 165, 45], [20, 30, 15]], np.uint16) * 256
    green = points.green_points(rgb, 0.1, 65535.0)
    assert green.tolist() == [False, False, True, False, False]  # soil, grey, leaf, yellow, too dark
    ret = np.array([[1, 1], [1, 3], [3, 3], [2, 2]], np.uint8)
    assert PointRule(returns=True).labels(None, Signals(returns=ret)).tolist() == [0, 1, 0, 0]


def test_colour_threshold_adapts_and_stays_off_bare_soil():
    """Otsu's split on a site with vegetation; the default on bare soil, brown or grey, which
    then flags almost nothing."""
    rng = np.random.default_rng(3)
    soil = np.clip(rng.normal([128, 102, 78], 6, (20000, 3)), 0, 255)
    grey = np.clip(rng.normal([118, 116, 110], 6, (20000, 3)), 0, 255)
    leaf = np.clip(rng.normal([90, 120, 60], 6, (3000, 3)), 0, 255)
    thr, scale = points.colour_threshold(np.vstack([soil, leaf]).astype(np.uint16))
    assert scale == 255.0 and 0.06 <= thr <= 0.2
    assert points.green_points(leaf.astype(np.uint16), thr, scale).mean() > 0.95
    for bare in (soil, grey):
        t, s = points.colour_threshold(bare.astype(np.uint16))
        assert points.green_points(bare.astype(np.uint16), t, s).mean() < 0.03  # isolated: no cell
    assert points.decide(None, Signals(rgb=leaf.astype(np.uint16)), "auto", "none").green is None


def _cone(shape, cell, x, y, r_bottom, r_top, height):
    yy, xx = (np.indices(shape) + 0.5) * cell
    r = np.hypot(xx - x, yy - y)
    return np.clip((r_bottom - r) * height / (r_bottom - r_top), 0.0, height)


def test_shape_moved_box_pair_versus_pile_and_pit():
    """Two boxes of matching size with vertical walls, one raised and one lowered, are a moved
    object; a 45 degree pile and a pit dug beside it of the same size are earthworks."""
    cell, shape = 0.5, (120, 160)
    d = np.zeros(shape)
    d[20:24, 20:29] = 1.6  # a 2 x 4.5 m vehicle where it is now
    d[80:89, 30:34] = -1.6  # and where it was, turned
    d += _cone(shape, cell, 55, 20, 7.0, 2.0, 3.0) - _cone(shape, cell, 55, 45, 7.0, 2.0, 3.0)
    fill, cut = d > 0.1, d < -0.1
    found = objects.find_objects(d, fill, cut, cell)
    moved = found.moved_blobs()
    assert len(moved) == 2 and {b.sign for b in moved} == {1, -1}
    assert found.moved[22, 25] and found.moved[85, 32]
    assert not found.moved[40, 110] and not found.single[40, 110] and not found.moved[90, 110]


def test_lone_box_left_out_steep_heap_counted():
    """Objects in one survey only: a container (vertical walls) is left out by default; a heap at
    its angle of repose and a blob larger than any machine are counted, whatever their walls.
    Measured slopes: box 2.6, heap 1.0 (rise/run)."""
    from soilvolume.volumes import nonsoil

    cell, shape = 0.5, (140, 160)
    d = np.zeros(shape)
    d[20:25, 20:32] = 2.6  # a 2.5 x 6 m container
    d += _cone(shape, cell, 55, 20, 4.0, 1.0, 3.0)  # a small heap, 45 degrees
    d[100:130, 100:150] = 2.6  # a 15 x 25 m walled bin of soil: no machine's volume
    fill = d > 0.1
    found = objects.find_objects(d, fill, np.zeros(shape, bool), cell)
    by_x = {round(b.x): b for b in found.single_blobs()}
    box = min(by_x.values(), key=lambda b: abs(b.x - 25.5))
    assert box.slope >= nonsoil.OBJECT_SLOPE and box.volume_m3 <= nonsoil.OBJECT_MAX_M3
    lone = nonsoil._lone(found)
    assert lone[22, 25] and not lone[40, 110] and not lone[115, 125]
    heap = [b for b in found.blobs if abs(b.x - 110) < 3]
    assert all(b.slope < nonsoil.OBJECT_SLOPE for b in heap)


def test_interval_carries_what_the_classification_may_miss(no_change):
    """The classification term (a share of the excluded volumes) and the correction's leftover
    are part of the interval."""
    _, auto, _ = no_change
    unc = auto["uncertainty"]
    assert unc["classification_m3"]["fill"] > 1.0
    assert "correction_residual_m3" in unc


def test_tiled_run_labels_points_as_in_process(no_change, tmp_path):
    """The tiled engine's tasks label their points with each epoch's rule (decided once, on the
    file's first chunk) and give the in-process result, excluded.tif included."""
    pair, auto, _ = no_change
    got = _run(pair, tmp_path / "r", scheduler="threads:2", tile_cells=24)
    assert got["engine"]["tiles"] > 4
    for part in ("net", "cut", "fill"):
        assert got["volume_m3"][part] == pytest.approx(auto["volume_m3"][part], rel=1e-3, abs=0.05)
    assert got["excluded"]["moved_objects"]["count"] == auto["excluded"]["moved_objects"]["count"]
    out = Path(auto["inputs"]["after"]["path"]).parents[1] / "auto"
    with rasterio.open(tmp_path / "r" / "excluded.tif") as g, rasterio.open(out / "excluded.tif") as r:
        assert np.mean(g.read(1) == r.read(1)) > 0.999


def test_no_signal_no_change_is_honest(tmp_path):
    """xyz only (no classification, colour or returns): no soil change, 3 vehicles moved, 5 grass
    patches grown, bushes grown. Shape alone cannot tell the grass and the unmatched vehicles from
    soil: the interval is widened by that change and holds 0; the verdict says the number is not
    reliable and why. Measured: net +47.0 m3 +- 69.7 m3, 53 m3 in 13 patches unclassified."""
    pair = _pair(tmp_path / "data", 57, change="none", signals="none", movers=3, patches=5)
    rep = _run(pair, tmp_path / "r")
    v, u = rep["volume_m3"], rep["uncertainty_m3"]
    assert v["fill"] > 20.0  # the grown vegetation is counted: nothing said it is not soil
    assert abs(v["net"]) <= u["net"] and v["cut"] <= u["cut"] and v["fill"] <= u["fill"]
    assert rep["quality"]["verdict"] == "not reliable"
    assert any(
        "could not be classified" in m and "no classification, colour or return" in m
        for m in rep["quality"]["messages"]
    )
    unclear = rep["excluded"]["unclassified"]
    assert unclear["count"] >= 3 and not unclear["signals"]
    assert rep["uncertainty"]["unclassified_m3"]["net"] >= 0.5 * v["fill"]


def test_no_signal_pile_stays_usable(tmp_path):
    """xyz only, one pile and 2 moved vehicles: the pile is no compact patch, so the interval
    stays narrow and the verdict is not "not reliable" for what could not be classified.
    Measured: net -4.5 % +- 7.7 % (a vehicle's old place unmatched: -9 m3), 11 m3 unclassified."""
    pair = _pair(tmp_path / "data", 58, change="pile", signals="none", movers=2, patches=0, vegetation=False)
    rep = _run(pair, tmp_path / "r")
    v, u, truth = rep["volume_m3"], rep["uncertainty_m3"], pair[2]["net"]
    assert v["net"] == pytest.approx(truth, rel=0.07)
    assert abs(v["net"] - truth) <= u["net"] <= 0.1 * truth
    assert rep["quality"]["verdict"] != "not reliable"
    assert rep["uncertainty"]["unclassified_m3"]["net"] <= 0.08 * truth


def test_verdict_on_what_could_not_be_classified():
    """Not reliable when, without any signal, the unclassified change is over the interval and a
    tenth of the net, or, with signals, over a tenth of the volume moved (the number may be off by
    that much); use with caution when only machine-sized objects in one survey are open and they are
    small against the volume moved; no word when it is small against the interval."""
    from soilvolume.volumes.quality import _unclassified

    def excluded(fill, cut, signals):
        unclear = {"fill": fill, "cut": cut, "net": fill - cut, "count": 3, "signals": signals}
        return {"unclassified": unclear, "bound_m3": {"fill": fill, "cut": cut, "net": max(fill, cut)}}

    ((sev, msg),) = _unclassified(excluded(150.0, 20.0, False), net=180.0, half=60.0, moved=2000.0)
    assert sev == "unreliable" and "from +30 to +200 m³" in msg and "no classification, colour" in msg
    ((sev, msg),) = _unclassified(excluded(15.0, 0.0, True), net=-2.0, half=8.0, moved=400.0)
    assert sev == "caution" and "machine-sized objects in one survey only" in msg
    ((sev, msg),) = _unclassified(excluded(15.0, 0.0, True), net=-2.0, half=8.0, moved=100.0)
    assert sev == "unreliable" and "more than 10% of the volume moved (100 m³)" in msg
    ((sev, msg),) = _unclassified(excluded(15.0, 0.0, True), net=90.0, half=20.0, moved=100.0)  # in the interval
    assert sev == "unreliable" and "more than 10% of the volume moved" in msg
    ((sev, msg),) = _unclassified(excluded(3.0, 0.0, True), net=0.5, half=2.0, moved=4.0)  # over a tenth moved
    assert sev == "unreliable" and "more than 10% of the volume moved (4 m³)" in msg
    assert _unclassified(excluded(6.0, 0.0, True), net=-7.5, half=10.6, moved=8.1) == []  # no change: in its noise
    ((sev, msg),) = _unclassified(excluded(15.0, 0.0, True), net=-1.4, half=7.5, moved=1.8)
    assert sev == "unreliable" and "more than the measurement error (±7.5 m³) of a job that moved 1.8 m³" in msg
    assert _unclassified(excluded(15.0, 0.0, False), net=900.0, half=40.0, moved=1000.0) == []  # within the interval
    assert _unclassified(excluded(50.0, 0.0, False), net=900.0, half=40.0, moved=1000.0) == []  # under a tenth


@pytest.mark.parametrize("seed", [126, 128])
def test_the_cut_is_the_pit_not_its_neighbours(tmp_path, seed):
    """The seed paper's piles and pit at 1.25 M points, grass grown, bushes, 2 vehicles moved,
    occlusion holes; RGB. A hole across the pit's rim beside a bush, holes beside parked machines
    and refilled bushes next to small noise cuts made the 69 m3 cut too large and its interval
    miss (seed 126: +7.6 %, +-6.7 %). Measured: cut +3.4 % (+-7.4 %) and +0.1 % (+-5.2 %), net
    -0.97 % and +0.77 %."""
    cfg = dict(before_points=1_250_000, after_points=750_000, shift_m=(3.0, 2.0, 0.5), rotation_deg=(0.5, -0.4, 3.0))
    cfg.update(doming_m=0.03, outlier_fraction=0.005, holes=8, vegetation=True, objects=True)
    b, a, t = write_pair_streaming(
        seed, SceneConfig(**cfg, signals="rgb", movers=2, patches=6, crops=True), tmp_path, "las"
    )
    truth = json.loads(Path(t).read_text())
    rep = _run((b, a), tmp_path / "r")
    for part, within in (("net", 0.015), ("cut", 0.045), ("fill", 0.015)):
        err = rep["volume_m3"][part] - truth[part]
        assert abs(err) <= within * truth[part], (part, err)
        assert abs(err) <= rep["uncertainty_m3"][part], (part, err, rep["uncertainty_m3"][part])
    assert rep["uncertainty"]["outline_m3"]["cut"] >= 0.0
