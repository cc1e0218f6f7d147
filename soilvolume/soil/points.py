"""What is soil, point by point: a rule (:class:`PointRule`) decided on each epoch's first chunk and
applied to every chunk alike, in-process and in the tiled tasks. Labels :data:`SOIL`,
:data:`VEGETATION`, :data:`OBJECT`, :data:`OTHER`.

* Classification (class 2 present): 2 soil; 3-5 vegetation; 6, 10, 13-17 objects; others other.
* Colour (RGB, no classification): vegetation where ExG = 2g - r - b (chromatic) exceeds the
  epoch's threshold and green is the strongest channel; the threshold is Otsu's split of the first
  chunk's ExG when it shows a green mode, clamped to 0.06..0.20, else 0.10; points too dark for a
  colour stay soil.
* Returns (no classification): a point before the last of several returns is vegetation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SOIL, VEGETATION, OBJECT, OTHER = 0, 1, 2, 3
GROUND = 2
_BY_CLASS = np.full(256, OTHER, np.uint8)
_BY_CLASS[GROUND] = SOIL
_BY_CLASS[[3, 4, 5]] = VEGETATION
_BY_CLASS[[6, 10, 13, 14, 15, 16, 17]] = OBJECT
GREEN_DEFAULT, GREEN_RANGE = 0.10, (0.06, 0.20)
DARK = 0.12  # r + g + b below this share of full scale: too dark for a colour
MIN_GREEN_SHARE = 0.002  # a green mode: at least this share of the first chunk's points
MIN_MULTI_RETURNS = 0.005  # returns are used when at least this share has several
RGB_DIMS, RETURN_DIMS = ("red", "green", "blue"), ("return_number", "number_of_returns")  # LAS dimensions


@dataclass(frozen=True)
class Signals:
    """Per-point fields of a chunk beyond xyz and the classification (None when absent)."""

    rgb: np.ndarray | None = None  # (n, 3) uint16
    returns: np.ndarray | None = None  # (n, 2) uint8: return number, number of returns

    def select(self, mask: np.ndarray) -> Signals:
        return Signals(*(None if a is None else a[mask] for a in (self.rgb, self.returns)))

    @staticmethod
    def join(parts) -> Signals | None:
        """The chunks' signals end to end (None when the first has none)."""
        if not parts or parts[0] is None:
            return None
        rgb, ret = ([getattr(p, k) for p in parts] for k in ("rgb", "returns"))
        return Signals(*(None if a[0] is None else np.concatenate(a) for a in (rgb, ret)))


@dataclass(frozen=True)
class PointRule:
    """How one epoch's points are labelled (see module); the default labels everything soil."""

    use_class: bool = False
    green: float | None = None  # ExG threshold; None: colour not used
    full_scale: float = 65535.0  # of the colour channels (255 for 8-bit colour)
    returns: bool = False

    @property
    def active(self) -> bool:
        return self.use_class or self.green is not None or self.returns

    @property
    def empties_cells(self) -> bool:
        """Whether a cell mostly of non-soil points has no soil height (photogrammetry: no ground
        under a canopy)."""
        return self.green is not None and not self.use_class

    @property
    def signal_dims(self) -> set[str]:
        """The LAS dimensions :meth:`labels` reads beyond the classification."""
        dims = set()
        if self.green is not None:
            dims.update(RGB_DIMS)
        if self.returns and not self.use_class:
            dims.update(RETURN_DIMS)
        return dims

    def class_table(self, has_class: bool) -> np.ndarray | None | bool:
        """The labels of the 256 LAS classes when the classification alone decides (None: all soil);
        False when colour or returns are needed."""
        if self.use_class and has_class:
            return _BY_CLASS
        if self.green is None and not (self.returns and not self.use_class):
            return None
        return False

    def labels(self, cls: np.ndarray | None, sig: Signals | None) -> np.ndarray | None:
        """uint8 labels of a chunk's points, or None when all are soil."""
        out = None
        if self.use_class and cls is not None:
            out = _BY_CLASS[np.asarray(cls, np.uint8)]
        if self.green is not None and sig is not None and sig.rgb is not None:
            veg = green_points(sig.rgb, self.green, self.full_scale)
            out = np.where(veg, VEGETATION, SOIL).astype(np.uint8) if out is None else out
        if self.returns and not self.use_class and sig is not None and sig.returns is not None:
            early = sig.returns[:, 0] < sig.returns[:, 1]
            out = np.zeros(len(early), np.uint8) if out is None else out
            out[early] = VEGETATION
        return out

    def describe(self) -> str:
        """The rule in words, for the report."""
        if not self.active:
            return "every point is soil (no classification, colour or returns used)"
        parts = []
        if self.use_class:
            parts.append(
                "LAS classification: class 2 is soil; 3-5 vegetation; 6, 10, 13-17 objects; others (noise 7/18, "
                "water 9, unclassified 1) not soil"
            )
        if self.green is not None:
            parts.append(f"colour: vegetation where ExG = 2g - r - b > {self.green:.3f} and green is the strongest")
        if self.returns and not self.use_class:
            parts.append("returns: points before the last of several returns are vegetation")
        return "; ".join(parts)


def exg(rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(ExG on chromatic coordinates, r + g + b) of (n, 3) colours."""
    c = rgb.astype(np.float32)
    total = c.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        index = (2 * c[:, 1] - c[:, 0] - c[:, 2]) / np.maximum(total, 1.0)
    return index, total


def green_points(rgb: np.ndarray, threshold: float, full_scale: float) -> np.ndarray:
    """Vegetation by colour (see module)."""
    index, total = exg(rgb)
    g = rgb[:, 1]
    return (index > threshold) & (g > rgb[:, 0]) & (g > rgb[:, 2]) & (total >= DARK * 3 * full_scale)


def otsu(values: np.ndarray, lo: float = -0.3, hi: float = 0.7, bins: int = 200) -> float:
    """Otsu's threshold of ``values`` on a histogram over lo..hi."""
    hist, edges = np.histogram(values, bins=bins, range=(lo, hi))
    p = hist.astype(float) / max(hist.sum(), 1)
    mid = 0.5 * (edges[1:] + edges[:-1])
    w0 = np.cumsum(p)
    m = np.cumsum(p * mid)
    with np.errstate(invalid="ignore", divide="ignore"):
        between = (m[-1] * w0 - m) ** 2 / (w0 * (1 - w0))
    return float(mid[int(np.nanargmax(np.nan_to_num(between, nan=-1.0)))])


def _uses_class(cls: np.ndarray | None, mode: str) -> bool:
    return mode == "class" or (mode == "auto" and cls is not None and bool((cls == GROUND).any()))


def _signals_may_decide(mode: str, exclude: str) -> bool:
    """Whether ``--ground`` and ``--exclude`` leave colour and returns a say in the rule."""
    return exclude != "none" and mode in ("auto", "class", "filter", "csf")


def deciding_dims(cls: np.ndarray | None, mode: str, exclude: str = "auto") -> set[str]:
    """The LAS dimensions :func:`decide` reads beyond the first chunk's classification ``cls``."""
    if _uses_class(cls, mode) or not _signals_may_decide(mode, exclude):
        return set()
    return {*RGB_DIMS, *RETURN_DIMS}


def decide(cls: np.ndarray | None, sig: Signals | None, mode: str, exclude: str = "auto") -> PointRule:
    """The epoch's rule from its first chunk, by ``--ground`` ``mode`` and ``--exclude``."""
    use_class = _uses_class(cls, mode)
    if use_class or sig is None or not _signals_may_decide(mode, exclude):
        return PointRule(use_class)
    green, scale = colour_threshold(sig.rgb) if sig.rgb is not None and len(sig.rgb) else (None, 65535.0)
    multi = sig.returns is not None and len(sig.returns) > 0
    return PointRule(use_class, green, scale, multi and float(np.mean(sig.returns[:, 1] > 1)) >= MIN_MULTI_RETURNS)


def colour_threshold(rgb: np.ndarray) -> tuple[float | None, float]:
    """(ExG threshold or None when the colour carries nothing, full scale of the channels)."""
    top = float(rgb.max())
    if top <= 0 or (rgb[:, 0] == rgb[:, 1]).all() and (rgb[:, 1] == rgb[:, 2]).all():
        return None, 65535.0  # no colour, or grey levels only
    scale = 255.0 if top <= 255 else 65535.0
    index, total = exg(rgb)
    bright = index[total >= DARK * 3 * scale]
    if bright.size < 100:
        return GREEN_DEFAULT, scale
    split = otsu(bright)
    green_mode = np.count_nonzero(bright > split) >= MIN_GREEN_SHARE * bright.size
    return (split if green_mode and GREEN_RANGE[0] <= split <= GREEN_RANGE[1] else GREEN_DEFAULT), scale


@dataclass(frozen=True)
class NonSoil:
    """One epoch's non-soil points (float32 local xyz, labels) and the rule that labelled them."""

    xyz: np.ndarray
    labels: np.ndarray
    rule: PointRule

    def moved(self, transform: np.ndarray | None) -> NonSoil:
        """The same points through a 4x4 rigid transform (float32 kept)."""
        if transform is None or not len(self.xyz):
            return self
        r, t = transform[:3, :3].astype(np.float32), transform[:3, 3].astype(np.float32)
        return NonSoil((self.xyz @ r.T + t).astype(np.float32), self.labels, self.rule)
