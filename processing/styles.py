"""Styling of the rasters the algorithms load: QML from ``resources/styles`` with the colour ramp
stretched to the layer's values (a difference symmetric around 0)."""

from __future__ import annotations

import math
from pathlib import Path

from qgis.core import (
    QgsCategorizedSymbolRenderer,
    QgsColorRampLegendNodeSettings,
    QgsFillSymbol,
    QgsMapLayer,
    QgsProcessingContext,
    QgsProcessingFeedback,
    QgsProcessingLayerPostProcessorInterface,
    QgsRasterLayer,
    QgsRendererCategory,
    QgsSingleBandPseudoColorRenderer,
    QgsVectorLayer,
)

STYLES_DIR = Path(__file__).resolve().parent.parent / "resources" / "styles"
DIVERGING = "difference"
TERRAIN = "dem"
MASK = "filled_mask"  # a 0/1 mask: 1 orange, half see-through
GRADE = "grade"  # classes: 1 cut to go red, 2 on grade green, 3 fill to go blue
CHANGE_AREAS = "change_areas"  # polygons: cut red, fill blue, by their "kind"
FILL_ALPHA = 40  # of 255: the change areas' light fill


def style_path(kind: str) -> Path:
    return STYLES_DIR / f"{kind}.qml"


def value_range(layer: QgsRasterLayer) -> tuple[float, float] | None:
    """The 2-98 % cumulative cut of band 1 (its min and max when the cut is undefined, as for a
    constant raster such as a zero correction), or None for an empty raster."""
    provider = layer.dataProvider()
    if provider is None:
        return None
    lo, hi = provider.cumulativeCut(1, 0.02, 0.98)
    if _finite(lo, hi):
        return float(lo), float(hi)
    return min_max(layer.source())


def min_max(path: str) -> tuple[float, float] | None:
    """Exact min and max of band 1 of a GDAL raster (None when it has no valid cell)."""
    from osgeo import gdal

    try:
        dataset = gdal.Open(path)
        lo, hi = dataset.GetRasterBand(1).ComputeRasterMinMax(False) if dataset else (None, None)
    except RuntimeError:  # no valid cell (GDAL exceptions enabled)
        return None
    return (float(lo), float(hi)) if _finite(lo, hi) else None


def _finite(*values: float | None) -> bool:
    return all(v is not None and math.isfinite(v) for v in values)


def style_change_areas(layer: QgsMapLayer) -> bool:
    """Cut polygons outlined red, fill polygons blue, by their ``kind``: a bold outline and a
    light fill (15 % opaque), so the difference raster under them stays readable."""
    if not isinstance(layer, QgsVectorLayer) or not layer.isValid():
        return False
    categories = []
    for value, colour in (("cut", "215,48,39"), ("fill", "33,102,172")):
        symbol = QgsFillSymbol.createSimple(
            {"color": f"{colour},{FILL_ALPHA}", "outline_color": f"{colour},255", "outline_width": "0.8"}
        )
        categories.append(QgsRendererCategory(value, symbol, value))
    layer.setRenderer(QgsCategorizedSymbolRenderer("kind", categories))
    layer.triggerRepaint()
    return True


def apply_style(layer: QgsMapLayer, kind: str) -> bool:
    """Load the QML for ``kind``, stretch its ramp to the data (symmetric for differences) and
    install it as a new renderer, so the Layers panel rebuilds the legend with the new range."""
    if kind == CHANGE_AREAS:
        return style_change_areas(layer)
    if not isinstance(layer, QgsRasterLayer) or not layer.isValid():
        return False
    _message, ok = layer.loadNamedStyle(str(style_path(kind)))
    renderer = layer.renderer()
    rng = value_range(layer)
    if ok and isinstance(renderer, QgsSingleBandPseudoColorRenderer) and rng is not None:
        layer.setRenderer(stretched(renderer, *symmetric(rng, kind)))
    layer.triggerRepaint()
    return ok


def symmetric(rng: tuple[float, float], kind: str) -> tuple[float, float]:
    """The styled range: centred on 0 for differences, never empty."""
    lo, hi = rng
    if kind == DIVERGING:
        m = max(abs(lo), abs(hi)) or 0.1
        return -m, m
    return (lo, hi) if hi > lo else (lo, lo + 1.0)


def stretched(renderer: QgsSingleBandPseudoColorRenderer, lo: float, hi: float):
    """A copy of ``renderer`` with its colour ramp (and legend) spread over lo..hi."""
    new = renderer.clone()
    ramp = renderer.shader().rasterShaderFunction().sourceColorRamp()
    legend = renderer.shader().rasterShaderFunction().legendSettings()
    new.setClassificationMin(lo)
    new.setClassificationMax(hi)
    new.createShader(ramp.clone() if ramp is not None else None)
    if legend is not None:
        new.shader().rasterShaderFunction().setLegendSettings(QgsColorRampLegendNodeSettings(legend))
    return new


class StylePostProcessor(QgsProcessingLayerPostProcessorInterface):
    """Applies :func:`apply_style` to a layer Processing loads on completion."""

    _alive: list[StylePostProcessor] = []  # Processing does not own post-processors

    def __init__(self, kind: str) -> None:
        super().__init__()
        self.kind = kind

    def postProcessLayer(  # noqa: N802 - Qt API
        self, layer: QgsMapLayer, context: QgsProcessingContext, feedback: QgsProcessingFeedback
    ) -> None:
        apply_style(layer, self.kind)

    @classmethod
    def create(cls, kind: str) -> StylePostProcessor:
        processor = cls(kind)
        cls._alive.append(processor)
        return processor


def style_on_load(
    context: QgsProcessingContext, path: str | None, kind: str, name: str = "", order: int = 0, group: str = ""
) -> None:
    """Style the output at ``path`` (name it, put it in ``group``, and stack it by ``order``:
    higher on top) if Processing will load it. In a group of its own, each run's stack is the
    same whatever layer is selected (Processing inserts at the top of a group, in key order)."""
    if not path or not context.willLoadLayerOnCompletion(path):
        return
    details = context.layerToLoadOnCompletionDetails(path)
    if kind:
        details.setPostProcessor(StylePostProcessor.create(kind))
    if name:
        details.name = name
    if group:
        details.groupName = group
    details.layerSortKey = order
