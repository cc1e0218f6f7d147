"""The QGIS plugin class (menu, toolbar, Processing provider registration)."""
