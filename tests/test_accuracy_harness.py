"""The accuracy harness's ground truth and scoring (issue 10): the new synthetic change kinds have
exact volumes, the excavation covers the requested share of the after footprint, features do not
overlap, clutter keeps off the change, and the harness scores a fabricated report correctly.
Fast (a few seconds): no estimate is run."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from soilvolume.scenes.synthetic import (
    SceneConfig,
    change_dz,
    feature_area,
    features_dz,
    make_pair,
    scene_truth,
)

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
import accuracy  # noqa: E402
import real_terrain  # noqa: E402

KINDS = [("pit", 0.4), ("pile", 0.4), ("excavation", 0.4), ("excavation", 0.5), ("excavation", 0.7)]


def _grid(box, cell):
    x0, y0, x1, y1 = box
    xs = x0 + (np.arange(int(round((x1 - x0) / cell))) + 0.5) * cell
    ys = y0 + (np.arange(int(round((y1 - y0) / cell))) + 0.5) * cell
    return xs, ys


def _local_features(truth, cfg):
    feats = []
    for f in truth["features"]:
        g = dict(f)
        g["x"] -= cfg.origin[0]
        g["y"] -= cfg.origin[1]
        feats.append(g)
    return feats


@pytest.mark.parametrize("change,fraction", KINDS, ids=[f"{c}{f}" for c, f in KINDS])
def test_new_change_kinds_truth(change, fraction):
    """Numeric volume of dz on a 5 cm grid over the after footprint equals the analytic truth
    within 0.5 % (cut and fill separately); features lie inside the after footprint and never
    overlap; the excavation's outline covers the requested fraction (+- 5 % of it)."""
    cfg = SceneConfig.small(change=change, change_fraction=fraction)
    t = scene_truth(1, cfg)
    o = cfg.origin
    fp = t["after_footprint"]
    box = (fp[0] - o[0], fp[1] - o[1], fp[2] - o[0], fp[3] - o[1])
    area = (box[2] - box[0]) * (box[3] - box[1])
    cell = 0.05
    xs, ys = _grid(box, cell)
    feats = _local_features(t, cfg)
    fill = cut = 0.0
    support = np.zeros((len(ys), len(xs)), np.int32)
    for i in range(0, len(ys), 400):
        yy = ys[i : i + 400, None]
        dz = change_dz(xs[None, :], yy, cfg)
        fill += dz[dz > 0].sum() * cell * cell
        cut -= dz[dz < 0].sum() * cell * cell
        for f in feats:
            support[i : i + 400] += features_dz(xs[None, :], yy, [f]) != 0
    assert support.max() <= 1, "features overlap"
    if t["fill"] > 0:
        assert fill == pytest.approx(t["fill"], rel=5e-3)
    else:
        assert fill == 0
    if t["cut"] > 0:
        assert cut == pytest.approx(t["cut"], rel=5e-3)
    else:
        assert cut == 0
    assert t["net"] == pytest.approx(t["fill"] - t["cut"])
    # every feature's outline is inside the after footprint
    for f in feats:
        r = f["r_bottom"] if f["kind"] == "cone" else None
        ext = (r, r) if r is not None else (f["a"], f["b"])
        assert box[0] < f["x"] - ext[0] and f["x"] + ext[0] < box[2]
        assert box[1] < f["y"] - ext[1] and f["y"] + ext[1] < box[3]
    if change == "excavation":
        exc = [f for f in feats if f["sign"] < 0]
        assert len(exc) == 1 and t["config"]["change_fraction"] == fraction
        assert feature_area(exc[0]) / area == pytest.approx(fraction, rel=1e-9)
        measured = (support.sum() * cell * cell - sum(feature_area(f) for f in feats if f["sign"] > 0)) / area
        assert measured == pytest.approx(fraction, rel=0.05)
    else:
        assert "change_fraction" not in t["config"]
        share = {"pit": 0.05, "pile": 0.10}[change]
        assert support.sum() * cell * cell / area == pytest.approx(share, rel=0.05)


def test_clutter_and_holes_keep_off_the_excavation():
    """Vegetation, vehicles and boulders are placed around the true outline of the new features
    (some inside the after footprint, none on the change)."""
    cfg = SceneConfig.small(
        change="excavation",
        change_fraction=0.5,
        vegetation=True,
        objects=True,
        holes=6,
        before_points=40_000,
        after_points=25_000,
    )
    scene = make_pair(2, cfg)
    cls = scene.before_class
    xy = scene.before[:, :2]
    clutter = (cls >= 3) & (cls <= 6)
    assert clutter.sum() > 50
    dz = scene.change_dz(xy[clutter, 0], xy[clutter, 1])
    assert np.all(dz == 0)
    fp = scene.truth["after_footprint"]
    inside = (xy[clutter, 0] > fp[0]) & (xy[clutter, 0] < fp[2]) & (xy[clutter, 1] > fp[1]) & (xy[clutter, 1] < fp[3])
    assert inside.sum() > 10


def test_real_terrain_features_exact():
    """The real-terrain cases' analytic volumes equal a 0.1 m raster integral within 0.5 %."""
    for case in real_terrain.CASES:
        feats = real_terrain.features(case)
        xs, ys = _grid(real_terrain.BOX, 0.1)
        for f in feats:
            r = f["radius"]
            m_x = (xs > f["x"] - r) & (xs < f["x"] + r)
            m_y = (ys > f["y"] - r) & (ys < f["y"] + r)
            dz = features_dz(xs[m_x][None, :], ys[m_y][:, None], [f])
            assert abs(dz.sum()) * 0.01 == pytest.approx(f["volume"], rel=5e-3)
        area = (real_terrain.BOX[2] - real_terrain.BOX[0]) * (real_terrain.BOX[3] - real_terrain.BOX[1])
        assert 0.05 < sum(feature_area(f) for f in feats) / area < 0.6


# --- scoring ----------------------------------------------------------------------------------


def _truth(net_cut_fill=(900.0, 100.0, 1000.0), yaw_deg=2.0):
    c = np.array([500_050.0, 3_900_050.0, 60.0])
    shift = np.array([2.0, -1.0, 0.3])
    a = math.radians(yaw_deg)
    R = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    T = np.eye(4)
    T[:3, :3] = R.T
    T[:3, 3] = c - R.T @ (c + shift)
    net, cut, fill = net_cut_fill
    return {
        "net": net,
        "cut": cut,
        "fill": fill,
        "transform": T.tolist(),
        "misalignment": {"center": c.tolist(), "shift_m": shift.tolist()},
    }, T


def test_score_on_a_fabricated_report():
    truth, T = _truth()
    # estimate: net +1 % (covered), cut +20 % (not covered), fill +2 % (covered); a transform
    # off by 0.1 degree of yaw about the true centre
    b = math.radians(0.1)
    E = np.eye(4)
    E[:3, :3] = [[math.cos(b), -math.sin(b), 0], [math.sin(b), math.cos(b), 0], [0, 0, 1]]
    c = np.array(truth["misalignment"]["center"])
    E[:3, 3] = c - E[:3, :3] @ c
    report = {
        "volume_m3": {"net": 909.0, "cut": 120.0, "fill": 1020.0},
        "uncertainty_m3": {"net": 10.0, "cut": 5.0, "fill": 25.0},
        "registration": {"transform": (E @ T).tolist()},
    }
    row = accuracy.score(report, truth, "paper", dense=True)
    assert row["err_pct"]["net"] == pytest.approx(1.0)
    assert row["err_pct"]["cut"] == pytest.approx(20.0)
    assert row["covered"] == {"net": True, "cut": False, "fill": True}
    assert row["hw_pct"]["net"] == pytest.approx(100 * 10 / 900)
    assert row["registration"]["rot_deg"] == pytest.approx(0.1, abs=1e-9)
    assert row["registration"]["shift_m"] == pytest.approx(0.0, abs=1e-6)  # rotation about it
    assert row["checks"] == {"net 1%": True, "cut 3%": False, "fill 3%": True, "net hw 5%": True}
    assert accuracy.passed(row) is False
    row2 = accuracy.score(
        {
            **report,
            "uncertainty_m3": {"net": 50.0, "cut": 30.0, "fill": 30.0},
            "volume_m3": {"net": 905.0, "cut": 101.0, "fill": 1006.0},
        },
        truth,
        "paper",
        dense=True,
    )
    assert row2["covered"] == {"net": True, "cut": True, "fill": True}
    assert row2["checks"]["net hw 5%"] is False  # 50 m3 > 5 % of 900 m3
    # coverage over rows, skipping rows without an interval or a truth
    rows = [row, row2, {"covered": {"net": None, "cut": None, "fill": None}}, {"error": "x"}]
    assert accuracy.coverage(rows) == {"net": (2, 2), "cut": (1, 2), "fill": (2, 2)}
    # a run with a truth that failed counts as a miss
    rows.append({"error": "registration failed", "has_truth": True})
    assert accuracy.coverage(rows) == {"net": (2, 3), "cut": (1, 3), "fill": (2, 3)}
    assert accuracy.passed(rows[-1]) is False
    assert accuracy.passed({"checks": {}}) is None


def test_zero_truth_errors_are_relative_to_the_moved_volume():
    truth, _ = _truth((-200.0, 200.0, 0.0))
    report = {
        "volume_m3": {"net": -190.0, "cut": 204.0, "fill": 14.0},
        "uncertainty_m3": {"net": 12.0, "cut": 10.0, "fill": 10.0},
    }
    row = accuracy.score(report, truth, "half", dense=False)
    assert row["err_pct"]["fill"] == pytest.approx(7.0)  # 14 m3 of 200 m3 moved
    assert row["covered"]["fill"] is False and row["covered"]["net"] is True
    assert row["checks"] == {"net 3%": False, "cut 5%": True, "fill 5%": False}
    assert math.isnan(accuracy.rel_error_pct(1.0, 0.0, 0.0))
    assert accuracy.covered(1.0, 0.0, None) is None


def test_verdict_and_option_notes():
    good = {
        "name": "a",
        "has_truth": True,
        "verdict": "reliable",
        "checks": {"net 1%": True},
        "covered": {"net": True},
        "est": {"net": 1.0},
    }
    bad = {
        "name": "b",
        "has_truth": True,
        "verdict": "reliable",
        "checks": {"net 1%": False},
        "covered": {"net": True},
        "est": {"net": 2.0},
    }
    worse = {"name": "c", "has_truth": True, "verdict": "not reliable", "error": "x"}
    (line,) = accuracy.verdict_summary([good, bad, worse])
    assert "reliable: 2 cases, 1 of them bad" in line and "not reliable: 1 cases, 1" in line
    assert "not reported" in accuracy.verdict_summary([{"name": "d"}])[0]
    diag = {**bad, "diagnostic": True}
    assert accuracy.verdict_summary([good, diag]) == accuracy.verdict_summary([good])
    twin = {**good, "name": "a-precise"}
    assert "a-precise" in accuracy.same_as_default([good, twin])[0]
    assert accuracy.same_as_default([good, {**twin, "est": {"net": 3.0}}]) == []


@pytest.mark.parametrize("kind", ["yard", "landslide", "trench", "pillars"])
def test_site_kinds_have_exact_volumes(kind):
    """The issue-19 site kinds: the analytic volumes equal a fine numeric integral of dz."""
    cfg = SceneConfig(change=kind, slope_deg=30.0 if kind == "landslide" else 0.0)
    truth = scene_truth(5, cfg)
    feats = _local_features(truth, cfg)
    xs, ys = _grid((0.0, 0.0, *cfg.before_size), 0.05)
    x, y = np.meshgrid(xs, ys)
    dz = features_dz(x, y, feats)
    fill, cut = dz[dz > 0].sum() * 0.0025, -dz[dz < 0].sum() * 0.0025
    assert fill == pytest.approx(truth["fill"], rel=5e-3, abs=0.5)
    assert cut == pytest.approx(truth["cut"], rel=5e-3, abs=0.5)
    if kind == "pillars":
        assert truth["fill"] == pytest.approx(1030.0, rel=0.01)


def test_counted_truth_and_no_change_scoring():
    """Objects in one survey only count as the engine counts them (an arrival and a departure of
    one size are a move); a no-change pair is scored in m3 and on its interval holding 0."""
    objects = [
        {"epoch": "before", "role": "moved", "area_m2": 9.0, "volume": 13.0},
        {"epoch": "after", "role": "moved", "area_m2": 9.0, "volume": 13.0},
        {"epoch": "after", "role": "arrived", "area_m2": 8.0, "volume": 12.0},
        {"epoch": "after", "role": "arrived", "area_m2": 20.0, "volume": 30.0},
        {"epoch": "before", "role": "left", "area_m2": 8.5, "volume": 12.5},
    ]
    t = accuracy.counted_truth({"net": 0.0, "cut": 0.0, "fill": 0.0, "one_epoch_objects": objects})
    assert (t["fill"], t["cut"], t["net"]) == (30.0, 0.0, 30.0)
    truth = {"net": 0.0, "cut": 0.0, "fill": 0.0}
    report = {"volume_m3": {"net": 9.0, "cut": 6.0, "fill": 15.0}, "uncertainty_m3": {"net": 10.0}}
    row = accuracy.score(report, truth, "nochange", False)
    assert all(row["checks"].values())
    report["uncertainty_m3"]["net"] = 8.0
    assert accuracy.score(report, truth, "nochange", False)["checks"]["0 in 95 %"] is False


def test_datum_target_needs_the_intervals_and_the_net_of_the_moved_volume():
    """Issue 45's rows: net within 1 % of cut + fill, cut and fill within 3 %, and each interval
    holding the truth; the datum cases and the series' periods are in the matrix."""
    truth, _ = _truth((74.0, 243.0, 317.0))
    report = {
        "volume_m3": {"net": 78.0, "cut": 242.0, "fill": 320.0},  # net +4 m3: 0.7 % of 560 m3 moved
        "uncertainty_m3": {"net": 6.0, "cut": 3.0, "fill": 2.0},  # fill's misses by 1 m3
    }
    row = accuracy.score(report, truth, "datum", dense=False, net_of_moved=True)
    assert row["err_pct"]["net"] == pytest.approx(100 * 4 / 560)
    assert row["checks"] == {"net 1%": True, "cut 3%": True, "fill 3%": True, "n/c/f in 95 %": False}
    names = {c.name for c in accuracy.MATRIX if c.target == "datum"}
    assert {"datum-gps3", "datum-gps5-exc", "datum-precise", *accuracy.DATUM_SERIES} <= names
