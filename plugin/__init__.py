"""The engine's environment for QGIS: built and checked (``environment``, ``interpreters``,
``platforms``), the engine run in it as a child process (``child``), the dependency bar
(``installer``). Imports nothing of ``processing/``, which runs the engine through it."""
