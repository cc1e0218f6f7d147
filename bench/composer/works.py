"""The soil works of a composed site: piles, pits, trenches, platforms, embankments, moved
stockpiles and compaction, drawn at random and placed apart on the after footprint.

Every work is a list of analytic features (:func:`..features.finish_features`: truncated cones and
rectangles with equal side slopes) whose exact volumes are the truth. A moved stockpile is a pile
standing in the before ground (``before``) that is gone in the after one (a cut of its volume) and
a pile of the same volume elsewhere (a fill). Coordinates: metres from the after footprint's
south-west corner.
"""

from __future__ import annotations

import math

import numpy as np

from soilvolume.scenes.features import finish_features

WORKS = ("pile", "pit", "trench", "platform", "embankment", "moved stockpile", "compaction")
WORK_P = (0.28, 0.2, 0.12, 0.1, 0.1, 0.1, 0.1)


def _cone(sign: float, rb: float, rt: float, h: float, name: str) -> dict:
    return dict(kind="cone", sign=sign, x=0.0, y=0.0, r_bottom=rb, r_top=rt, height=h, exact_outline=True, name=name)


def _rect(sign: float, a: float, b: float, h: float, run: float, angle: float, name: str) -> dict:
    run = min(run, 0.95 * min(a, b))
    return dict(
        kind="rect",
        sign=sign,
        x=0.0,
        y=0.0,
        a=a,
        b=b,
        height=h,
        run=run,
        angle_deg=angle,
        exact_outline=True,
        name=name,
    )


def _pile(rng: np.random.Generator, span: float, sign: float = 1.0, name: str = "pile") -> dict:
    """A cone or a rectangular pile, from a barrow-load to thousands of m3, sides 25-40 degrees."""
    r = float(math.exp(rng.uniform(math.log(1.5), math.log(0.22 * span))))
    slope = math.tan(math.radians(rng.uniform(25.0, 40.0)))
    if rng.random() < 0.6:
        top = float(rng.uniform(0.0, 0.6)) * r
        return _cone(sign, r, top, (r - top) * slope, f"{name} (cone)")
    a, b = r, float(rng.uniform(0.4, 1.0)) * r
    h = float(rng.uniform(0.3, 0.9)) * b * slope
    return _rect(sign, a, b, h, h / slope, float(rng.uniform(0, 180)), f"{name} (rectangular)")


def _pit(rng: np.random.Generator, span: float) -> dict:
    """A pit, shallow to 4 m deep, from gentle to near-vertical sides."""
    r = float(math.exp(rng.uniform(math.log(1.5), math.log(0.2 * span))))
    depth = float(rng.uniform(0.3, 4.0))
    run = min(0.9 * r, depth / math.tan(math.radians(rng.uniform(30.0, 85.0))))
    if rng.random() < 0.5:
        return _cone(-1.0, r, max(r - run, 0.0), depth, "pit (cone)")
    b = float(rng.uniform(0.5, 1.0)) * r
    return _rect(-1.0, r, b, depth, run, float(rng.uniform(0, 180)), "pit (rectangular)")


def _work_features(kind: str, rng: np.random.Generator, span: float) -> tuple[list[dict], list[dict]]:
    """(after-minus-before features, features standing in the before ground) of one work."""
    ang = float(rng.uniform(0, 180))
    if kind == "pile":
        return [_pile(rng, span)], []
    if kind == "pit":
        return [_pit(rng, span)], []
    if kind == "trench":  # narrow and deep, walls near vertical
        a, b, d = float(rng.uniform(0.2, 0.45)) * span, float(rng.uniform(0.4, 1.5)), float(rng.uniform(0.8, 3.0))
        return [_rect(-1.0, a, b, d, float(rng.uniform(0.05, 0.35)) * b, ang, "trench")], []
    if kind == "platform":  # a wide flat fill
        a, b, h = (
            float(rng.uniform(0.08, 0.2)) * span,
            float(rng.uniform(0.06, 0.15)) * span,
            float(rng.uniform(0.3, 2.0)),
        )
        return [_rect(1.0, a, b, h, h * float(rng.uniform(1.0, 2.0)), ang, "platform")], []
    if kind == "embankment":  # long, 1-4 m high, 1:1.5 sides
        h = float(rng.uniform(0.8, 3.5))
        a, b = float(rng.uniform(0.2, 0.4)) * span, h * 1.5 + float(rng.uniform(1.0, 3.0))
        return [_rect(1.0, a, b, h, h * 1.5, ang, "embankment")], []
    if kind == "compaction":  # a wide settlement of a few centimetres to 0.25 m
        a, b, d = (
            float(rng.uniform(0.08, 0.2)) * span,
            float(rng.uniform(0.08, 0.2)) * span,
            float(rng.uniform(0.04, 0.25)),
        )
        return [_rect(-1.0, a, b, d, float(rng.uniform(0.5, 3.0)), ang, "compaction")], []
    old = _pile(rng, span, 1.0, "stockpile before")
    gone = dict(old, sign=-1.0, name="stockpile removed")
    new = dict(old, name="stockpile moved here")
    if new["kind"] == "rect":
        new["angle_deg"] = float(rng.uniform(0, 180))
    return [gone, new], [old]


def _place(rng: np.random.Generator, feats: list[dict], placed: list, aw: float, ah: float) -> bool:
    """Give every feature of a work a free spot on the footprint (1 m margins); False if none."""
    spots = []
    for f in feats:
        r = f["radius"]
        if 2 * r + 2 > min(aw, ah):
            return False
        for _ in range(60):
            x, y = float(rng.uniform(r + 1, aw - r - 1)), float(rng.uniform(r + 1, ah - r - 1))
            if all(math.hypot(x - px, y - py) > r + pr + 1.0 for px, py, pr in placed + spots):
                spots.append((x, y, r))
                break
        else:
            return False
    for f, (x, y, _) in zip(feats, spots, strict=True):
        f["x"], f["y"] = x, y
    placed.extend(spots)
    return True


def draw_works(rng: np.random.Generator, aw: float, ah: float) -> list[dict]:
    """1-6 works (a few sites none) of random kinds and sizes, apart on an ``aw`` x ``ah`` footprint."""
    span = min(aw, ah)
    n = 0 if rng.random() < 0.04 else int(rng.integers(1, 7))
    placed: list = []
    works = []
    for _ in range(n):
        kind = WORKS[int(rng.choice(len(WORKS), p=WORK_P))]
        for _try in range(8):
            change, before = _work_features(kind, rng, span)
            finish_features(change)
            finish_features(before)
            if _place(rng, change, placed, aw, ah):
                break
        else:
            continue
        for b, c in zip(before, change, strict=False):  # the old stockpile stands where it was removed
            b["x"], b["y"] = c["x"], c["y"]
        works.append({"kind": kind, "change": change, "before": before, "size": _size(change)})
    return works


def _size(change: list[dict]) -> dict:
    f = change[-1]
    extent = 2 * f["r_bottom"] if f["kind"] == "cone" else max(2 * f["a"], 2 * f["b"])
    return {
        "volume_m3": round(sum(c["volume"] for c in change), 1),
        "height_m": round(f["height"], 2),
        "extent_m": round(extent, 1),
    }
