"""soilvolume: soil volume change from two georeferenced point clouds (engine, no QGIS needed)."""

__version__ = "0.6.0"
