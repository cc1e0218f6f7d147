"""Step 5: grids, heights, holes, change areas, volumes and their uncertainty."""

from __future__ import annotations

from .table import CELLS, DESIGNED, ESTIMATE, GRID, GROUND, GROUND_FILTER, POINTS, VOLUME, option, options

HELP = {
    "cell": "grid cell size (m); default from the before cloud's density (>= 8 points per cell, >= 0.5 m)",
    "statistic": "per-cell height: robust-mean (mean after rejecting points beyond 3 MAD of the cell median), mean (the paper), median",
    "min_count_ratio": "a cell of one epoch with fewer points than this fraction of its median count (and always one with fewer than 3) is unreliable: its height is re-filled from neighbours (0 = off)",
    "fill_holes": "fill enclosed holes (cells empty in either epoch, e.g. occlusions) up to this area (m2) by interpolating the height difference around them; larger holes stay empty and are reported (0 = off)",
    "fill_method": "interpolation of refilled cells: biharmonic (smooth, keeps slopes across the hole), harmonic (Laplace, never overshoots its border values)",
    "ground": "ground points: auto (class 2 when the file has ground-classified points, judged on its first million points; else all), class (class 2 only), filter (SMRF ground filter), csf (cloth simulation filter, tuned for earthworks: a 0.5 m cloth of medium stiffness that follows piles and pits and bridges vehicles and bushes; needs the cloth-simulation-filter package), none",
    "ground_window": "{opt:ground=filter}: largest object (m) the SMRF filter removes (vehicles, bushes); keep it below the width of the piles you measure (PDAL's default 18 m removes piles)",
    "ground_slope": "{opt:ground=filter}: steepest ground slope (rise/run) SMRF keeps as terrain (pile flanks; PDAL's default 0.15)",
    "exclude": "what is not soil: auto (points the signals say are not soil are not gridded: the LAS classification as {opt:ground} selects it, colour (vegetation by its excess-green index) and return numbers on files without one; objects that moved between the surveys are left out of the headline; objects in one survey only as {opt:objects} says), none (colour and returns not used, moved objects and objects in one survey only counted: the volumes {opt:exclude=auto} lists are restored; the class-2 selection stays with {opt:ground})",
    "objects": "objects in one survey only (a machine, a container, a cabin or a stack of materials that arrived or left, found by their near-vertical walls): exclude (left out of the headline and listed with their volume; only earthworks count), count (counted as fill or cut and listed: the seed paper's test pillars)",
    "lod_confidence": "confidence of the level of detection and of the volume uncertainty",
    "zones": "optional polygon file: volumes per polygon (a series with a design: its progress per polygon)",
    "design_uncertainty": "when BEFORE is a surface (a design DEM GeoTIFF): its vertical uncertainty (m, one sigma, common to the "
    "compared area), added to the volumes' interval; 0 takes the design as exact",
    "contour_interval": "write contours.gpkg: contour lines every this many metres of the difference (layer difference: ELEV below 0 "
    "is cut, above 0 fill, 0 their border) and of each DEM (layers dem_before, dem_after), by GDAL's contour "
    "algorithm, none across nodata (0 = none)",
    "sections": "a vector file of lines (any OGR format; its CRS honoured): a cross-section along each, the heights before "
    "(the design against a surface), after and their difference every half cell, in sections.csv (line id and "
    "name, chainage in m, x, y, before, after, difference) and one picture per line, sections/NAME.svg",
    "gpkg": "also write the areas of significant change as change_areas.gpkg and, with {opt:zones}, the zones with their "
    "budgets as zones.gpkg (GeoPackage, in the run's CRS; zones.csv is written with {opt:zones} either way)",
    "design_surface": "when BEFORE is a LandXML file: the name of its TIN surface to use (default: the file's first surface)",
    "bulking": "bulking (swell) factor, loose/bank volume (e.g. 1.25): report.json's quantities give the loose volumes "
    "(a zone's own: its 'bulking' attribute in the zones file)",
    "shrinkage": "shrinkage factor, compacted/bank volume (e.g. 0.90): report.json's quantities give the compacted volumes "
    "(a zone's own: its 'shrinkage' attribute in the zones file)",
    "tolerance": "when BEFORE is a design: the on-grade tolerance (m, e.g. 0.05): grade.tif classes each cell as cut to go "
    "(survey above design by more than it), on grade or fill to go; report.json's grade gives the share on "
    "grade and the cut and fill still to go, overall and per zone",
    "design": "a series' design surface (a DEM GeoTIFF or a LandXML TIN), resampled onto the series' grid: with "
    "{opt:tolerance}, each epoch's share on grade and cut and fill still to go, and each period's progress "
    "(the cut and fill to go it did)",
}


@options(HELP)
class VolumeOptions:
    """Step 5: grids, heights, holes, change areas, volumes and their uncertainty."""

    # step 5: grids and volumes
    cell: float | None = option(None, "Grid cell size", GRID, "m", 0.01, 1000.0)
    statistic: str = option("robust-mean", "Per-cell height statistic", GRID, choices=("robust-mean", "mean", "median"))
    min_count_ratio: float = option(0.1, "Weak cell threshold (fraction of the median count)", CELLS, None, 0.0, 1.0)
    fill_holes: float = option(100.0, "Largest hole to fill", VOLUME, "m2", 0.0, 1e7)
    fill_method: str = option("biharmonic", "Hole interpolation", VOLUME, choices=("biharmonic", "harmonic"))
    ground: str = option("auto", "Ground points", GROUND, choices=("auto", "class", "filter", "csf", "none"))
    ground_window: float = option(6.0, "Ground filter window", GROUND_FILTER, "m", 0.5, 500.0)
    ground_slope: float = option(0.6, "Ground filter slope (rise/run)", GROUND_FILTER, None, 0.01, 10.0)
    exclude: str = option("auto", "Exclude what is not soil", POINTS, choices=("auto", "none"))
    objects: str = option("exclude", "Objects in one survey only", VOLUME, choices=("exclude", "count"))
    lod_confidence: float = option(0.95, "Confidence level", VOLUME, None, 0.5, 0.999)
    zones: str | None = option(None, "Zones (polygons)", DESIGNED)
    design_uncertainty: float = option(0.0, "Design uncertainty (a surface as BEFORE)", ESTIMATE, "m", 0.0, 100.0)
    contour_interval: float = option(0.0, "Contour interval", ESTIMATE, "m", 0.0, 10000.0, run_control=True)
    sections: str | None = option(None, "Cross-section lines", run_control=True)
    gpkg: bool = option(False, "GeoPackage copies of the change areas and zones", run_control=True)
    design_surface: str | None = option(None, "LandXML surface name (a LandXML design as BEFORE)", DESIGNED)
    bulking: float | None = option(None, "Bulking factor (loose/bank)", VOLUME, None, 0.0, 10.0, lo_open=True)
    shrinkage: float | None = option(None, "Shrinkage factor (compacted/bank)", VOLUME, None, 0.0, 10.0, lo_open=True)
    tolerance: float | None = option(
        None, "On-grade tolerance (a design as BEFORE)", DESIGNED, "m", 0.0, 100.0, lo_open=True
    )
    design: str | None = option(None, "Design surface (a series' progress)", ("series",))
