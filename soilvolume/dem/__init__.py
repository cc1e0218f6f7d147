"""Step 4: average-height grids (DEMs) of both epochs on one shared grid, unreliable and empty
cells refilled, GeoTIFF writing.
"""
