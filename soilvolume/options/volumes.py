"""Step 5: grids, heights, holes, change areas, volumes and their uncertainty."""

from __future__ import annotations

from dataclasses import dataclass

from .table import CELLS, DESIGNED, GRID, GROUND, GROUND_FILTER, POINTS, VOLUME, option


@dataclass(frozen=True)
class VolumeOptions:
    """Step 5: grids, heights, holes, change areas, volumes and their uncertainty."""

    # step 5: grids and volumes
    cell: float | None = option(
        None,
        "grid cell size (m); default from the before cloud's density (>= 8 points per cell, >= 0.5 m)",
        label="Grid cell size",
        unit="m",
        lo=0.01,
        hi=1000.0,
        commands=GRID,
    )
    statistic: str = option(
        "robust-mean",
        "per-cell height: robust-mean (mean after rejecting points beyond 3 MAD of the cell median), mean (the paper), median",
        ("robust-mean", "mean", "median"),
        label="Per-cell height statistic",
        commands=GRID,
    )
    min_count_ratio: float = option(
        0.1,
        "a cell of one epoch with fewer points than this fraction of its median count (and always one with fewer than 3) is unreliable: its height is re-filled from neighbours (0 = off)",
        label="Weak cell threshold (fraction of the median count)",
        lo=0.0,
        hi=1.0,
        commands=CELLS,
    )
    fill_holes: float = option(
        100.0,
        "fill enclosed holes (cells empty in either epoch, e.g. occlusions) up to this area (m2) by interpolating the height difference around them; larger holes stay empty and are reported (0 = off)",
        label="Largest hole to fill",
        unit="m2",
        lo=0.0,
        hi=1e7,
        commands=VOLUME,
    )
    fill_method: str = option(
        "biharmonic",
        "interpolation of refilled cells: biharmonic (smooth, keeps slopes across the hole), harmonic (Laplace, never overshoots its border values)",
        ("biharmonic", "harmonic"),
        label="Hole interpolation",
        commands=VOLUME,
    )
    ground: str = option(
        "auto",
        "ground points: auto (class 2 when the file has ground-classified points, judged on its first million points; else all), class (class 2 only), filter (SMRF ground filter), csf (cloth simulation filter, tuned for earthworks: a 0.5 m cloth of medium stiffness that follows piles and pits and bridges vehicles and bushes; needs the cloth-simulation-filter package), none",
        ("auto", "class", "filter", "csf", "none"),
        label="Ground points",
        commands=GROUND,
    )
    ground_window: float = option(
        6.0,
        "{opt:ground=filter}: largest object (m) the SMRF filter removes (vehicles, bushes); keep it below the width of the piles you measure (PDAL's default 18 m removes piles)",
        label="Ground filter window",
        unit="m",
        lo=0.5,
        hi=500.0,
        commands=GROUND_FILTER,
    )
    ground_slope: float = option(
        0.6,
        "{opt:ground=filter}: steepest ground slope (rise/run) SMRF keeps as terrain (pile flanks; PDAL's default 0.15)",
        label="Ground filter slope (rise/run)",
        lo=0.01,
        hi=10.0,
        commands=GROUND_FILTER,
    )
    exclude: str = option(
        "auto",
        "what is not soil: auto (points the signals say are not soil are not gridded: the LAS classification as {opt:ground} selects it, colour (vegetation by its excess-green index) and return numbers on files without one; objects that moved between the surveys are left out of the headline; objects in one survey only as {opt:objects} says), none (colour and returns not used, moved objects and objects in one survey only counted: the volumes {opt:exclude=auto} lists are restored; the class-2 selection stays with {opt:ground})",
        ("auto", "none"),
        label="Exclude what is not soil",
        commands=POINTS,
    )
    objects: str = option(
        "exclude",
        "objects in one survey only (a machine, a container, a cabin or a stack of materials that arrived or left, found by their near-vertical walls): exclude (left out of the headline and listed with their volume; only earthworks count), count (counted as fill or cut and listed: the seed paper's test pillars)",
        ("exclude", "count"),
        label="Objects in one survey only",
        commands=VOLUME,
    )
    lod_confidence: float = option(
        0.95,
        "confidence of the level of detection and of the volume uncertainty",
        label="Confidence level",
        lo=0.5,
        hi=0.999,
        commands=VOLUME,
    )
    zones: str | None = option(
        None,
        "optional polygon file: volumes per polygon (a series with a design: its progress per polygon)",
        label="Zones (polygons)",
        commands=DESIGNED,
    )
    design_uncertainty: float = option(
        0.0,
        "when BEFORE is a surface (a design DEM GeoTIFF): its vertical uncertainty (m, one sigma, common to the "
        "compared area), added to the volumes' interval; 0 takes the design as exact",
        label="Design uncertainty (a surface as BEFORE)",
        unit="m",
        lo=0.0,
        hi=100.0,
    )
    contour_interval: float = option(
        0.0,
        "write contours.gpkg: contour lines every this many metres of the difference (layer difference: ELEV below 0 "
        "is cut, above 0 fill, 0 their border) and of each DEM (layers dem_before, dem_after), by GDAL's contour "
        "algorithm, none across nodata (0 = none)",
        label="Contour interval",
        unit="m",
        lo=0.0,
        hi=10000.0,
        run_control=True,
    )
    sections: str | None = option(
        None,
        "a vector file of lines (any OGR format; its CRS honoured): a cross-section along each, the heights before "
        "(the design against a surface), after and their difference every half cell, in sections.csv (line id and "
        "name, chainage in m, x, y, before, after, difference) and one picture per line, sections/NAME.svg",
        label="Cross-section lines",
        run_control=True,
    )
    gpkg: bool = option(
        False,
        "also write the areas of significant change as change_areas.gpkg and, with {opt:zones}, the zones with their "
        "budgets as zones.gpkg (GeoPackage, in the run's CRS; zones.csv is written with {opt:zones} either way)",
        label="GeoPackage copies of the change areas and zones",
        run_control=True,
    )
    design_surface: str | None = option(
        None,
        "when BEFORE is a LandXML file: the name of its TIN surface to use (default: the file's first surface)",
        label="LandXML surface name (a LandXML design as BEFORE)",
        commands=DESIGNED,
    )
    bulking: float | None = option(
        None,
        "bulking (swell) factor, loose/bank volume (e.g. 1.25): report.json's quantities give the loose volumes "
        "(a zone's own: its 'bulking' attribute in the zones file)",
        label="Bulking factor (loose/bank)",
        lo=0.0,
        lo_open=True,
        hi=10.0,
        commands=VOLUME,
    )
    shrinkage: float | None = option(
        None,
        "shrinkage factor, compacted/bank volume (e.g. 0.90): report.json's quantities give the compacted volumes "
        "(a zone's own: its 'shrinkage' attribute in the zones file)",
        label="Shrinkage factor (compacted/bank)",
        lo=0.0,
        lo_open=True,
        hi=10.0,
        commands=VOLUME,
    )
    tolerance: float | None = option(
        None,
        "when BEFORE is a design: the on-grade tolerance (m, e.g. 0.05): grade.tif classes each cell as cut to go "
        "(survey above design by more than it), on grade or fill to go; report.json's grade gives the share on "
        "grade and the cut and fill still to go, overall and per zone",
        label="On-grade tolerance (a design as BEFORE)",
        unit="m",
        lo=0.0,
        lo_open=True,
        hi=100.0,
        commands=DESIGNED,
    )
    design: str | None = option(
        None,
        "a series' design surface (a DEM GeoTIFF or a LandXML TIN), resampled onto the series' grid: with "
        "{opt:tolerance}, each epoch's share on grade and cut and fill still to go, and each period's progress "
        "(the cut and fill to go it did)",
        label="Design surface (a series' progress)",
        commands=("series",),
    )
