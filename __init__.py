"""QGIS plugin "Soil volume change": the repository root is the plugin folder.

QGIS imports this folder as a package named after it (``soilvolume_qgis`` when installed); all
plugin code uses relative imports so the ``processing/`` subfolder never shadows QGIS's own
Processing framework.
"""

from __future__ import annotations

import configparser
from pathlib import Path
from typing import Any

PLUGIN_DIR = Path(__file__).resolve().parent


def plugin_version() -> str:
    """The version in metadata.txt."""
    parser = configparser.ConfigParser()
    parser.read(PLUGIN_DIR / "metadata.txt", encoding="utf-8")
    return parser.get("general", "version", fallback="unknown")


def classFactory(iface: Any):  # noqa: N802 - QGIS plugin entry point
    """Called by QGIS to create the plugin object."""
    from .qgisplugin import SoilVolumePlugin

    return SoilVolumePlugin(iface)
