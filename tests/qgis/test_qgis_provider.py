"""The provider, its algorithms' metadata, and the Processing-shadowing guard."""

from __future__ import annotations

import sys
from pathlib import Path

from qgis.core import QgsApplication

REPO = Path(__file__).resolve().parents[2]
ALGORITHMS = {
    "estimatevolumechange",
    "volumeseries",
    "pointcloudtodem",
    "registerpointclouds",
    "volumefromdems",
    "stockpilevolumes",
    "installdependencies",
}


def test_processing_is_qgis_framework(qgis_processing, plugin_package):
    import processing

    path = Path(processing.__file__).resolve()
    assert REPO not in path.parents, f"the repo's processing/ shadows QGIS's: {path}"
    assert hasattr(processing, "run") and hasattr(processing, "execAlgorithmDialog")
    from qgis import processing as qgis_processing_module

    assert qgis_processing_module.run is processing.run
    import soilvolume_qgis.processing.provider as provider_module

    assert provider_module.__name__.startswith(plugin_package.__name__ + ".processing")
    assert all(Path(p or ".").resolve() != REPO for p in sys.path)


def test_provider_registers_all_algorithms(provider):
    registry = QgsApplication.processingRegistry()
    assert registry.providerById("soilvolume") is provider
    assert provider.name() == "Soil volume change"
    assert {a.name() for a in provider.algorithms()} == ALGORITHMS
    for name in ALGORITHMS:
        assert registry.algorithmById(f"soilvolume:{name}") is not None


def test_algorithms_are_documented(provider):
    for alg in provider.algorithms():
        assert alg.name() == alg.name().lower()
        assert alg.displayName() and alg.group() and alg.groupId()
        help_text = alg.shortHelpString()
        assert len(help_text) > 300 and "Output" in help_text and "Input" in help_text
        assert not alg.icon().isNull()
        assert alg.createInstance() is not alg
        for param in alg.parameterDefinitions():
            assert param.description(), f"{alg.name()}: {param.name()} has no description"


def test_numeric_outputs_of_the_estimate(provider):
    alg = QgsApplication.processingRegistry().algorithmById("soilvolume:estimatevolumechange")
    outputs = {o.name() for o in alg.outputDefinitions()}
    assert {"NET_VOLUME", "CUT_VOLUME", "FILL_VOLUME", "UNCOMPENSATED_NET_VOLUME"} <= outputs
    rasters = {"DIFFERENCE", "DEM_BEFORE", "DEM_AFTER", "PLANE_OFFSET"}
    assert rasters | {"REGISTERED", "REPORT"} <= outputs
    fine = alg.parameterDefinition("FINE")
    assert fine.options() == ["icp", "gicp", "pfh", "none"] and fine.usesStaticStrings()
    assert alg.parameterDefinition("CORRECTION").defaultValue() == "surface"


def test_plugin_menu_and_unload(plugin_package, qgis_iface):
    registry = QgsApplication.processingRegistry()
    before = registry.providerById("soilvolume")
    if before is not None:
        registry.removeProvider(before)
    plugin = plugin_package.classFactory(qgis_iface)
    plugin.initGui()
    try:
        assert registry.providerById("soilvolume") is not None
        assert plugin.action is not None and plugin.action.text().startswith("Estimate")
    finally:
        plugin.unload()
    assert registry.providerById("soilvolume") is None
    assert plugin.action is None
