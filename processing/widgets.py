"""Dialog widgets of two kinds of input, set on a parameter through its ``widget_wrapper`` metadata
(which QGIS's Processing dialogs honour; Batch and Model Builder keep QGIS's own widgets):

- :func:`no_default_layer`: a required layer input whose dropdown starts empty. QGIS preselects
  the project's first layer of a required layer parameter, so a difference raster or an earlier
  run's DEM silently became the *before* surface of a run; now the dialog asks for the layer
  ("Wrong or missing parameter value") until the user picks one.
- :func:`file_list`: a list of files in a given order (the series' surveys). QGIS's multiple-layer
  widget turns the paths it is given into layers and keeps only those it could load, so LAS/LAZ
  paths set before the dialog opened (``execAlgorithmDialog``) were lost where QGIS has no PDAL.
"""

from __future__ import annotations

from typing import Any

from qgis.core import QgsMapLayer, QgsProcessingContext, QgsProcessingParameterDefinition
from qgis.gui import (
    QgsAbstractProcessingParameterWidgetWrapper,
    QgsFileWidget,
    QgsGui,
    QgsProcessingGui,
    QgsProcessingMapLayerComboBox,
)
from qgis.PyQt import sip

DIALOG_TYPES = {  # Processing's dialog classes that are not the algorithm dialog
    "BatchAlgorithmDialog": QgsProcessingGui.WidgetType.Batch,
    "ModelerParametersDialog": QgsProcessingGui.WidgetType.Modeler,
}


class EmptyFirstWrapper(QgsAbstractProcessingParameterWidgetWrapper):
    """QGIS's layer dropdown (with its file button and drag and drop) built for an optional copy
    of the parameter, so it has an empty entry and starts on it; the parameter itself stays
    required, so the dialog refuses to run without a layer or file."""

    def __init__(self, param: QgsProcessingParameterDefinition, kind, **_options: Any) -> None:
        super().__init__(param, kind)
        self._optional: QgsProcessingParameterDefinition | None = None

    def createWidget(self):  # noqa: N802 - Qt API
        param = self.parameterDefinition()
        self._optional = param.dropdown() if hasattr(param, "dropdown") else param.clone()  # a file-typed input's
        self._optional.setFlags(self._optional.flags() | QgsProcessingParameterDefinition.FlagOptional)
        combo = QgsProcessingMapLayerComboBox(self._optional, self.type())
        combo.setToolTip(self.parameterDefinition().toolTip())
        combo.valueChanged.connect(lambda: self.widgetValueHasChanged.emit(self))
        combo.setWidgetContext(self.widgetContext())
        return combo

    def combo(self) -> QgsProcessingMapLayerComboBox | None:
        """The dropdown (QGIS owns it once created: its first Python object is not kept valid)."""
        return created(self, QgsProcessingMapLayerComboBox)

    def setWidgetContext(self, context) -> None:  # noqa: N802 - Qt API
        super().setWidgetContext(context)
        if self.combo() is not None:
            self.combo().setWidgetContext(context)

    def setWidgetValue(self, value: Any, context: QgsProcessingContext) -> None:  # noqa: N802 - Qt API
        if self.combo() is not None:
            self.combo().setValue(value, context)

    def widgetValue(self) -> Any:  # noqa: N802 - Qt API
        return self.combo().value() if self.combo() is not None else None


class FileListWrapper(QgsAbstractProcessingParameterWidgetWrapper):
    """A file picker of several files (``"a.las" "b.las"``, editable, in the order given): the
    value is the list of paths, kept as given (a layer given is its source file)."""

    def __init__(self, param: QgsProcessingParameterDefinition, kind, file_filter: str = "") -> None:
        super().__init__(param, kind)
        self.filter = file_filter

    def createWidget(self):  # noqa: N802 - Qt API
        files = QgsFileWidget()
        files.setStorageMode(QgsFileWidget.StorageMode.GetMultipleFiles)
        files.setFilter(self.filter)
        files.setToolTip(self.parameterDefinition().toolTip())
        files.fileChanged.connect(lambda _text: self.widgetValueHasChanged.emit(self))
        return files

    def files(self) -> QgsFileWidget | None:
        """The file picker (QGIS owns it once created)."""
        return created(self, QgsFileWidget)

    def setWidgetValue(self, value: Any, context: QgsProcessingContext) -> None:  # noqa: N802 - Qt API
        if self.files() is not None:
            self.files().setFilePath(" ".join(f'"{path}"' for path in file_paths(value)))

    def widgetValue(self) -> Any:  # noqa: N802 - Qt API
        text = self.files().filePath().strip() if self.files() is not None else ""
        return QgsFileWidget.splitFilePaths(text) if text else None


def created(wrapper: QgsAbstractProcessingParameterWidgetWrapper, kind: type):
    """The widget ``wrapper.createWidget`` made, as a ``kind`` (None before or after its life):
    the Python object it returned is not kept valid once QGIS owns the widget, and QGIS hands it
    back as a plain QWidget."""
    widget = wrapper.wrappedWidget()
    if widget is None or sip.isdeleted(widget):
        return None
    return widget if isinstance(widget, kind) else sip.cast(widget, kind)


def file_paths(value: Any) -> list[str]:
    """The paths in a value of a list-of-files parameter: a list (layers as their source files), or
    one string of paths separated by ';'."""
    if value is None:
        return []
    items = [v for v in value.split(";") if v.strip()] if isinstance(value, str) else list(value)
    return [item.source() if isinstance(item, QgsMapLayer) else str(item) for item in items]


class _InTheAlgorithmDialog:
    """A ``widget_wrapper`` class, which Processing instantiates as ``(param, dialog, row, col,
    **options)``: ``WRAPPER`` in the algorithm dialog, QGIS's own wrapper elsewhere."""

    WRAPPER: type = EmptyFirstWrapper

    def __new__(cls, param, dialog, row: int = 0, col: int = 0, **options: Any):  # noqa: ARG004 - Processing's call
        kind = DIALOG_TYPES.get(type(dialog).__name__, QgsProcessingGui.WidgetType.Standard)
        registry = QgsGui.processingGuiRegistry()
        if kind == QgsProcessingGui.WidgetType.Modeler:
            return registry.createModelerParameterWidget(dialog.model, dialog.childId, param, dialog.context)
        if kind == QgsProcessingGui.WidgetType.Standard:
            wrapper = cls.WRAPPER(param, kind, **options)
        else:
            wrapper = registry.createParameterWidgetWrapper(param, kind)
        wrapper.setDialog(dialog)
        return wrapper


class EmptyLayerChoice(_InTheAlgorithmDialog):
    WRAPPER = EmptyFirstWrapper


class FileListChoice(_InTheAlgorithmDialog):
    WRAPPER = FileListWrapper


def no_default_layer(param: QgsProcessingParameterDefinition) -> QgsProcessingParameterDefinition:
    """``param`` with a dialog dropdown that starts empty (see the module)."""
    param.setMetadata({**param.metadata(), "widget_wrapper": {"class": EmptyLayerChoice}})
    return param


def file_list(param: QgsProcessingParameterDefinition, file_filter: str) -> QgsProcessingParameterDefinition:
    """``param`` with a dialog widget that keeps the files it is given, in order (see the module)."""
    param.setMetadata({**param.metadata(), "widget_wrapper": {"class": FileListChoice, "file_filter": file_filter}})
    return param
