"""Styling of the rasters the algorithms load: QML from ``resources/styles`` with the colour ramp
stretched to the layer's values (a difference symmetric around 0)."""

from __future__ import annotations

from pathlib import Path

from qgis.core import (
    QgsMapLayer,
    QgsProcessingContext,
    QgsProcessingFeedback,
    QgsProcessingLayerPostProcessorInterface,
    QgsRasterLayer,
    QgsSingleBandPseudoColorRenderer,
)

STYLES_DIR = Path(__file__).resolve().parent.parent / "resources" / "styles"
DIVERGING = "difference"
TERRAIN = "dem"


def style_path(kind: str) -> Path:
    return STYLES_DIR / f"{kind}.qml"


def value_range(layer: QgsRasterLayer) -> tuple[float, float] | None:
    """The 2-98 % cumulative cut of band 1, or None for an empty raster."""
    provider = layer.dataProvider()
    if provider is None:
        return None
    lo, hi = provider.cumulativeCut(1, 0.02, 0.98)
    if lo is None or hi is None or lo != lo or hi != hi:  # NaN
        return None
    return float(lo), float(hi)


def apply_style(layer: QgsMapLayer, kind: str) -> bool:
    """Load the QML for ``kind`` and stretch its ramp to the data (symmetric for differences)."""
    if not isinstance(layer, QgsRasterLayer) or not layer.isValid():
        return False
    _message, ok = layer.loadNamedStyle(str(style_path(kind)))
    renderer = layer.renderer()
    rng = value_range(layer)
    if ok and isinstance(renderer, QgsSingleBandPseudoColorRenderer) and rng is not None:
        lo, hi = rng
        if kind == DIVERGING:
            m = max(abs(lo), abs(hi)) or 0.1
            lo, hi = -m, m
        elif hi <= lo:
            hi = lo + 1.0
        shader_fn = renderer.shader().rasterShaderFunction()
        ramp = shader_fn.sourceColorRamp()
        renderer.setClassificationMin(lo)
        renderer.setClassificationMax(hi)
        renderer.createShader(ramp.clone() if ramp is not None else None)
    layer.triggerRepaint()
    return ok


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
    context: QgsProcessingContext, path: str | None, kind: str, name: str = ""
) -> None:
    """Style the output at ``path`` (and name it) if Processing will load it."""
    if not path or not context.willLoadLayerOnCompletion(path):
        return
    details = context.layerToLoadOnCompletionDetails(path)
    details.setPostProcessor(StylePostProcessor.create(kind))
    if name:
        details.name = name
