"""The plugin's Processing provider and algorithms.

Imported only as a subpackage of the plugin (``soilvolume_qgis.processing``): the plugin folder
must never be on ``sys.path``, or this folder would shadow QGIS's own ``processing`` framework.
"""
