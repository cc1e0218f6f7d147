"""The tiled Dask engine: the same method with the point work done as tasks (scan, tiles, schedule,
COG writing).
"""
