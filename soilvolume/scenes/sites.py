"""The ``cone`` and ``rect`` features, and further sites (``SceneConfig.change``): a stockpile yard, a
landslide (on ``slope_deg`` about 30), a trench with its spoil, the seed paper's three pillars."""

from __future__ import annotations

WALL = 0.01  # horizontal run (m) of a vertical wall


def cone(sign, x, y, rb, rt, h, name, exact: bool = True) -> dict:
    """A flat-topped cone (``sign`` +1) or conical pit (-1); ``exact``: keep clear of its true outline."""
    return _named(dict(kind="cone", sign=sign, x=x, y=y, r_bottom=rb, r_top=rt, height=h), exact, name)


def rect(sign, x, y, a, b, h, run, angle, name, exact: bool = True) -> dict:
    """A flat-topped pile or excavation: half-sizes ``a`` x ``b``, height, side ``run``, ``angle`` deg."""
    return _named(dict(kind="rect", sign=sign, x=x, y=y, a=a, b=b, height=h, run=run, angle_deg=angle), exact, name)


def _named(f: dict, exact: bool, name: str) -> dict:
    if exact:
        f["exact_outline"] = True
    f["name"] = name
    return f


def site_features(kind: str, cx: float, cy: float, s: float) -> list[dict]:
    """The features of a site kind around the after footprint's centre (scaled by ``s``)."""
    if kind == "yard":  # six stockpiles of different shapes, one a long windrow
        return [
            cone(1.0, cx - 21 * s, cy + 13 * s, 7.0 * s, 2.0 * s, 4.5 * s, "yard: peaked cone"),
            cone(1.0, cx, cy + 15 * s, 6.0 * s, 3.0 * s, 3.0 * s, "yard: flat-topped cone"),
            rect(1.0, cx + 20 * s, cy + 14 * s, 7.0 * s, 4.0 * s, 2.5 * s, 2.5 * s, 10.0, "yard: bay pile"),
            rect(1.0, cx - 13 * s, cy - 14 * s, 12.0 * s, 2.2 * s, 1.8 * s, 1.8 * s, 0.0, "yard: windrow"),
            cone(1.0, cx + 8 * s, cy - 12 * s, 5.0 * s, 1.0 * s, 3.5 * s, "yard: small cone"),
            rect(1.0, cx + 23 * s, cy - 13 * s, 5.0 * s, 5.0 * s, 3.0 * s, 3.0 * s, 45.0, "yard: square pile"),
        ]
    if kind == "landslide":  # the scarp upslope (east) emptied, the toe downslope filled
        return [
            rect(-1.0, cx + 13 * s, cy, 7.0 * s, 10.0 * s, 2.2 * s, 3.0 * s, 0.0, "landslide scarp"),
            rect(1.0, cx - 14 * s, cy + 1 * s, 9.0 * s, 12.0 * s, 1.9 * s, 4.0 * s, 0.0, "landslide deposit"),
        ]
    if kind == "trench":  # a 3 m wide, 2 m deep trench across the survey, its spoil beside it
        return [
            rect(-1.0, cx, cy - 6 * s, 31.0 * s, 1.5 * s, 2.0 * s, 0.5 * s, 6.0, "trench"),
            rect(1.0, cx, cy + 4 * s, 24.0 * s, 2.6 * s, 1.5 * s, 2.1 * s, 6.0, "spoil windrow"),
        ]
    if kind == "pillars":  # Shao et al.: three pillars put on the after model, 1030 m3
        return [
            rect(1.0, cx - 16 * s, cy + 10 * s, 4.0 * s, 4.0 * s, 6.0 * s, WALL, 0.0, "pillar: box 8 x 8 x 6 m"),
            rect(1.0, cx + 14 * s, cy + 12 * s, 5.0 * s, 3.0 * s, 5.0 * s, WALL, 20.0, "pillar: box 10 x 6 x 5 m"),
            cone(1.0, cx + 2 * s, cy - 14 * s, 4.7 * s, 4.7 * s - WALL, 5.0 * s, "pillar: cylinder r 4.7 m"),
        ]
    raise ValueError(f"unknown site kind {kind!r}")
