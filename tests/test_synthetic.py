"""Tests of the synthetic scene generator (truth, determinism, frames, files)."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from soilvolume.scenes.synthetic import (
    Scene,
    SceneConfig,
    change_dz,
    iter_epoch,
    make_pair,
    scene_truth,
    write_pair,
    write_pair_streaming,
)


@pytest.fixture(scope="module")
def scene() -> Scene:
    return make_pair(
        3,
        SceneConfig.small(
            doming_m=0.03, vertical_bias_m=0.05, outlier_fraction=0.005, holes=6, vegetation=True, objects=True
        ),
    )


def _apply(T, xyz):
    T = np.asarray(T)
    return xyz @ T[:3, :3].T + T[:3, 3]


@pytest.fixture(params=["fixed", "drawn seed 3", "drawn seed 11"])
def any_scene(request, scene) -> Scene:
    """The module's scene, and two whose works the seed draws (truth only: no point sampled)."""
    if request.param == "fixed":
        return scene
    seed = int(request.param.split()[-1])
    cfg = SceneConfig.small(works="drawn")
    return Scene(None, None, None, None, scene_truth(seed, cfg), cfg, seed)


def test_truth_matches_fine_raster_integral(any_scene):
    """The analytic volumes agree with a 2 cm raster integral of dz to better than 0.05 %."""
    scene = any_scene
    cfg = scene.config
    cell = 0.02
    fill = cut = 0.0
    for f in scene.truth["features"]:
        r = f["radius"] + 0.1
        x0, y0 = f["x"] - cfg.origin[0] - r, f["y"] - cfg.origin[1] - r
        xs = x0 + (np.arange(int(2 * r / cell)) + 0.5) * cell
        ys = y0 + (np.arange(int(2 * r / cell)) + 0.5) * cell
        dz = change_dz(xs[None, :], ys[:, None], cfg, scene.seed)
        fill += dz[dz > 0].sum() * cell * cell
        cut -= dz[dz < 0].sum() * cell * cell
        assert abs(abs(dz.sum()) * cell * cell - f["volume"]) < 5e-4 * f["volume"]
    t = scene.truth
    assert abs(fill - t["fill"]) < 5e-4 * t["fill"]
    assert abs(cut - t["cut"]) < 5e-4 * t["cut"]
    assert t["net"] == pytest.approx(t["fill"] - t["cut"])
    if cfg.works == "fixed":
        assert 900 < t["fill"] < 1100 and 50 < t["cut"] < 100
    # dz vanishes outside the features, and on the whole before footprint the raster sum agrees
    xs = (np.arange(int(cfg.before_size[0] / 0.05)) + 0.5) * 0.05
    ys = (np.arange(int(cfg.before_size[1] / 0.05)) + 0.5) * 0.05
    rows = range(0, len(ys), 500)
    total = sum(change_dz(xs[None, :], ys[i : i + 500, None], cfg, scene.seed).sum() for i in rows)
    assert total * 0.05**2 == pytest.approx(t["net"], rel=5e-4)


def test_change_inside_after_footprint(any_scene):
    ax0, ay0, ax1, ay1 = any_scene.truth["after_footprint"]
    feats = any_scene.truth["features"]
    for f in feats:
        assert ax0 + 5 < f["x"] - f["radius"] and f["x"] + f["radius"] < ax1 - 5
        assert ay0 + 5 < f["y"] - f["radius"] and f["y"] + f["radius"] < ay1 - 5
    for i, f in enumerate(feats):  # and the works do not overlap
        for g in feats[i + 1 :]:
            assert np.hypot(f["x"] - g["x"], f["y"] - g["y"]) > f["radius"] + g["radius"], (f, g)


SEEDS = (0, 1, 2, 3, 5, 7)


def test_fixed_works_are_the_same_for_every_seed():
    """The default layout (bench/ACCURACY.md, the README, demo and self-test use it): one truth
    whatever the seed, +953.77 m3 on the small scene."""
    nets = {seed: round(scene_truth(seed, SceneConfig.small())["net"], 2) for seed in SEEDS}
    assert set(nets.values()) == {953.77}, nets


def test_the_seed_draws_the_works():
    """works="drawn": the seed draws the piles and pits. Before it could, seeds 0, 1, 2, 3, 5 and
    7 all gave +953.77 m3 from the same four works; now their counts, shapes, sizes, orientations
    and positions differ from seed to seed, in the range of the fixed layout."""
    truths = {seed: scene_truth(seed, SceneConfig.small(works="drawn")) for seed in SEEDS}
    nets = {seed: round(t["net"], 2) for seed, t in truths.items()}
    assert len(set(nets.values())) == len(SEEDS), nets
    counts = {tuple(sum(f["sign"] == s for f in t["features"]) for s in (1, -1)) for t in truths.values()}
    assert len(counts) >= 3, counts
    kinds = {f["kind"] for t in truths.values() for f in t["features"] if f["sign"] > 0}
    assert kinds == {"cone", "rect"}, kinds
    places = {(round(t["features"][0]["x"]), round(t["features"][0]["y"])) for t in truths.values()}
    assert len(places) == len(SEEDS), places
    for t in truths.values():
        assert 2 <= sum(f["sign"] > 0 for f in t["features"]) <= 4 and t["cut"] > 0
        assert 250 < t["fill"] < 2000 and 20 < t["cut"] < 300, (t["fill"], t["cut"])
        assert all(3.0 <= f["height"] <= 3.5 if f["sign"] > 0 else 1.0 <= f["height"] <= 1.6 for f in t["features"])
    again = scene_truth(3, SceneConfig.small(works="drawn"))
    assert again == truths[3]  # deterministic


def test_drawn_works_are_only_for_the_piles_site():
    with pytest.raises(ValueError, match="works 'drawn' applies to change 'piles'"):
        scene_truth(0, SceneConfig.small(change="pit", works="drawn"))
    with pytest.raises(ValueError, match="unknown works"):
        scene_truth(0, SceneConfig.small(works="random"))


def test_no_change_scene():
    t = scene_truth(0, SceneConfig.small(change="none"))
    assert t["net"] == t["cut"] == t["fill"] == 0.0


def test_deterministic(scene):
    again = make_pair(3, scene.config)
    # numpy's SIMD transcendental functions may differ by 1 ulp with memory alignment
    np.testing.assert_allclose(again.before, scene.before, rtol=0, atol=1e-9)
    np.testing.assert_allclose(again.after, scene.after, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(again.after_class, scene.after_class)
    assert again.truth == scene.truth
    other = make_pair(4, scene.config)
    assert other.before.shape != scene.before.shape or not np.array_equal(other.before, scene.before)


def test_truth_transform_recovers_true_frame(scene):
    """Surveyed after cloud mapped by truth["transform"] == the same sampling without any
    misalignment (the misalignment draws no random numbers)."""
    aligned = make_pair(3, replace(scene.config, shift_m=(0.0, 0.0, 0.0), rotation_deg=(0.0, 0.0, 0.0)))
    np.testing.assert_allclose(aligned.before, scene.before, rtol=0, atol=1e-9)
    recovered = _apply(scene.truth["transform"], scene.after)
    assert np.abs(recovered - aligned.after).max() < 1e-6
    # and the misalignment is really there
    assert np.abs(scene.after - aligned.after).max() > 1.0
    np.testing.assert_array_equal(aligned.after_class, scene.after_class)


def test_geometry_and_classes(scene):
    cfg = scene.config
    o = np.asarray(cfg.origin)
    lo, hi = scene.before.min(0) - o, scene.before.max(0) - o
    assert lo[0] >= 0 and lo[1] >= 0
    assert hi[0] <= cfg.before_size[0] and hi[1] <= cfg.before_size[1]
    g = scene.before_class == 2
    assert 45 < np.median(scene.before[g, 2]) < 80
    assert abs(len(scene.before) - cfg.before_points) < 0.1 * cfg.before_points
    assert abs(len(scene.after) - cfg.after_points) < 0.1 * cfg.after_points
    for cls in (scene.before_class, scene.after_class):
        assert cls.dtype == np.uint8
        assert set(np.unique(cls)) <= {1, 2, 3, 4, 5, 6}
        assert (cls == 2).mean() > 0.8
        assert ((cls >= 3) & (cls <= 5)).any() and (cls == 6).any() and (cls == 1).any()
    # vegetation grew: more vegetation points in the after epoch's footprint than before
    ax0, ay0, ax1, ay1 = scene.truth["after_footprint"]
    b = scene.before
    inside = (b[:, 0] > ax0) & (b[:, 0] < ax1) & (b[:, 1] > ay0) & (b[:, 1] < ay1)
    veg_b = ((scene.before_class >= 3) & (scene.before_class <= 5) & inside).sum() / inside.sum()
    veg_a = ((scene.after_class >= 3) & (scene.after_class <= 5)).mean()
    assert veg_a > veg_b


def test_after_heights_match_truth_on_ground():
    """Without nuisances, aligned after-minus-before ground heights show the dz field."""
    cfg = SceneConfig.small(noise_m=0.0, shift_m=(0, 0, 0), rotation_deg=(0, 0, 0))
    s = make_pair(1, cfg)
    from scipy.spatial import cKDTree

    tree = cKDTree(s.before[:, :2])
    d, i = tree.query(s.after[:, :2])
    diff = s.after[:, 2] - s.before[i, 2]
    dz = s.change_dz(s.after[:, 0], s.after[:, 1])
    flat = (dz == 0) & (d < 0.2)
    assert np.abs(diff[flat]).mean() < 0.1
    top = dz > 2.9
    assert abs(np.median(diff[top]) - np.median(dz[top])) < 0.2


def test_streaming_chunks_equal_in_memory(scene, monkeypatch):
    before = np.concatenate([xyz for xyz, _ in iter_epoch(3, scene.config, "before")])
    np.testing.assert_allclose(before, scene.before, rtol=0, atol=1e-9)
    import soilvolume.scenes.world as syn

    monkeypatch.setattr(syn, "CHUNK_POINTS", 7_000)  # many chunks
    s = make_pair(3, scene.config)
    assert abs(len(s.before) - len(scene.before)) < 0.01 * len(scene.before)
    chunks = list(iter_epoch(3, scene.config, "after"))
    assert len(chunks) > 3
    np.testing.assert_array_equal(np.concatenate([c for _, c in chunks]), s.after_class)
    # rows stay in order: the chunks tile the footprint without gaps or overlaps
    assert np.abs(np.concatenate([x for x, _ in chunks]) - s.after).max() < 1e-9


@pytest.mark.parametrize("fmt", ["las", "laz"])
def test_write_pair_roundtrip(scene, tmp_path, fmt):
    laspy = pytest.importorskip("laspy")
    pyproj = pytest.importorskip("pyproj")
    pb, pa, pt = write_pair(scene, tmp_path, fmt=fmt)
    assert pb.name == f"before.{fmt}" and pa.name == f"after.{fmt}"
    for path, xyz, cls in ((pb, scene.before, scene.before_class), (pa, scene.after, scene.after_class)):
        las = laspy.read(path)
        assert las.header.version.major == 1 and las.header.version.minor == 4
        crs = las.header.parse_crs()
        assert crs is not None and crs.equals(pyproj.CRS("EPSG:32654"))
        got = np.column_stack([las.x, las.y, las.z])
        assert np.abs(got - xyz).max() <= 0.0005 + 1e-9
        np.testing.assert_array_equal(np.asarray(las.classification), cls)
    truth = json.loads(pt.read_text())
    assert truth["net"] == pytest.approx(scene.truth["net"])
    assert np.allclose(truth["transform"], scene.truth["transform"])
    # streaming writer gives identical files' content
    sb, sa, st = write_pair_streaming(3, scene.config, tmp_path / "s", fmt=fmt)
    a1, a2 = laspy.read(pa), laspy.read(sa)
    assert np.abs(np.asarray(a1.X) - np.asarray(a2.X)).max() <= 1
    np.testing.assert_array_equal(np.asarray(a1.classification), np.asarray(a2.classification))
    assert a2.header.parse_crs().equals(pyproj.CRS("EPSG:32654"))
    assert json.loads(st.read_text()) == truth


def test_paper_config():
    cfg = SceneConfig.paper()
    assert cfg.before_points == 2_500_000 and cfg.after_points == 1_500_000
    assert cfg.vegetation and cfg.objects and cfg.holes > 0 and cfg.outlier_fraction > 0
    assert SceneConfig.paper(holes=0).holes == 0
    big = cfg.with_total_points(1_000_000)
    assert big.before_points + big.after_points == 1_000_000


def test_declared_vertical_datum_is_written(tmp_path):
    """SceneConfig.vertical_datum: the files declare a compound CRS (UTM 54N + NAVD88 height),
    whatever GPS error they carry; without it, the horizontal CRS alone (as before)."""
    import laspy

    from soilvolume.registration.georef import vertical_datum

    cfg = SceneConfig.declared_datum(before_points=3000, after_points=2000)
    assert cfg.vertical_datum == "EPSG:5703" and cfg.shift_m != (0.0, 0.0, 0.0)
    before, after, truth = write_pair(make_pair(3, cfg), tmp_path / "datum")
    for path in (before, after):
        crs = laspy.read(path).header.parse_crs()
        assert crs.is_compound and vertical_datum(crs.to_wkt()) == "NAVD88 height"
        assert crs.sub_crs_list[0].to_epsg() == 32654
    assert json.loads(truth.read_text())["config"]["vertical_datum"] == "EPSG:5703"
    plain = write_pair(make_pair(3, SceneConfig.small(before_points=3000, after_points=2000)), tmp_path / "plain")
    assert laspy.read(plain[1]).header.parse_crs().to_epsg() == 32654
