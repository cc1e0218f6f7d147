"""``soilvolume stockpile``: one survey read as ``dem`` reads it (its ground and soil points), gridded by the
one cell rule, its stockpile inventory (:mod:`soilvolume.stockpile`) written all or nothing."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import shapely

from .. import __version__
from ..core.hooks import Hooks
from ..core.outputs import check_input_file, output_dir
from ..core.types import GridSpec, survey
from ..dem.grid import average_height
from ..inputs.prepare import Single
from ..inputs.surface import on_grid, open_surface, read_over
from ..options import Options
from ..stockpile import Base, Inventory, Pile, PileError, Survey, parse_base, stockpile_inventory
from ..stockpile.html import write_html
from ..stockpile.map import map_png
from ..stockpile.reader import local_piles, read_piles
from ..stockpile.survey import fill_nearest, standard_errors
from ..stockpile.writers import report_piles, write_csv, write_gpkg
from . import steps
from .context import Context
from .plan import cloud_cell, plan_grid

STEPS = ("prepare", "grid", "volume", "write")
OUTPUTS = ("report.json", "report.html", "piles.csv", "piles.gpkg")


@dataclass(frozen=True)
class PileInput:
    """The toe polygons asked for: a vector file (None: find the piles) and its fields."""

    path: Path | None = None
    name_field: str | None = None
    density_field: str | None = None


def run_stockpile(
    cloud: Path,
    out: Path,
    options: Options,
    *,
    crs: str | None,
    pipeline: Path | None = None,
    piles: PileInput = PileInput(),
    overwrite: bool = False,
    hooks: Hooks | None = None,
) -> dict:
    """See :mod:`soilvolume.cli.stockpile`: bad input is refused before the output folder is made."""
    check_input_file(cloud)
    given = read_piles(piles.path, piles.name_field, piles.density_field) if piles.path else None
    base_text, surface_path = _base_text(options.base)
    source = open_surface(surface_path, crs) if surface_path else None
    hooks = hooks or Hooks()
    ctx = Context((survey(cloud, pipeline, crs=crs),), options, hooks, STEPS)
    with output_dir(out, [cloud, pipeline, piles.path, surface_path], overwrite, OUTPUTS) as folder:
        with steps.running(ctx, "prepare", ctx.message("prepare"), "crop"):
            one = steps.read_one(ctx)
        with steps.running(ctx, "grid", ctx.message("grid"), "grids"):
            grid, pile_survey = _grid(one, options)
        with steps.running(ctx, "volume", "measuring the piles"):
            base = _base(base_text, source, grid, one)
            local = _inside(local_piles(*given, grid), grid, piles.path) if given else None
            inventory = stockpile_inventory(pile_survey, local, base, options.density)
        with steps.running(ctx, "write", ctx.message("write")):
            report = _report(cloud, piles.path, grid, one, inventory, options)
            _write(folder, report, inventory, pile_survey)
    hooks.step(100, "done")
    return {"out": str(folder.final), "piles": len(inventory.piles), "volume_m3": report["volume_m3"]}


def _base_text(text: str) -> tuple[str, Path | None]:
    """The base option checked now (a typo is refused before any point is read): its text, and
    the raster of ``surface:DEM``."""
    kind, _, arg = text.strip().partition(":")
    if kind.lower() != "surface":
        parse_base(text)
        return text, None
    if not arg:
        raise PileError(f"base '{text}': surface:DEM needs a GeoTIFF path")
    path = Path(arg)
    check_input_file(path)
    return text, path


def _grid(one: Single, options: Options) -> tuple[GridSpec, Survey]:
    """The survey's grid (its points' box, the one cell rule) and its :class:`Survey` on it."""
    xyz = one.xyz.astype(np.float64)
    grid = plan_grid(cloud_cell(one.xyz, one.thin, options), [xyz], one.origin, one.frame, "no grid")
    h, n = average_height(xyz, grid, options.statistic)
    return grid, Survey(grid, h, n, standard_errors(xyz, grid, h, n), fill_nearest(h))


def _base(text: str, source, grid: GridSpec, one: Single) -> Base:
    """The :class:`Base` of ``text`` in the local frame: ``elevation:Z`` less the origin's height,
    ``surface:DEM`` resampled onto the grid (GDAL's warp, :func:`soilvolume.inputs.surface.on_grid`)."""
    if source is None:
        base = parse_base(text)
        return base if base.z is None else Base("elevation", z=base.z - float(one.origin[2]))
    surface = read_over(source, *grid.box(), one.frame, 2 * grid.cell)
    return parse_base("surface", on_grid(surface, grid) - grid.origin[2])


def _inside(piles: list[Pile], grid: GridSpec, path: Path | None) -> list[Pile]:
    """``piles``, each checked to lie at least partly over the survey's grid."""
    lo, hi = grid.box()
    extent = shapely.box(*(lo - np.asarray(grid.origin[:2])), *(hi - np.asarray(grid.origin[:2])))
    for p in piles:
        if not p.polygon.intersects(extent):
            raise PileError(f"{path}: pile '{p.name}' lies outside the survey")
    return piles


def _report(cloud: Path, path: Path | None, grid: GridSpec, one: Single, inv: Inventory, options: Options) -> dict:
    """report.json: the survey, the grid, the base, the piles and their warnings."""
    piles = report_piles(inv)
    return {
        "software": {"name": "soilvolume", "version": __version__},
        "product": "stockpile",
        "survey": str(cloud),
        "piles_file": None if path is None else str(path),
        "piles_found": inv.found,
        "crs_wkt": grid.crs_wkt,
        "cell_m": grid.cell,
        "origin": [float(v) for v in one.origin],
        "noise_m": round(inv.noise_m, 4),
        "base": options.base,
        "density_t_m3": options.density,
        "volume_m3": round(inv.volume_m3, 3),
        "tonnes": _tonnes(piles),
        "piles": piles,
        "warnings": [f"{p['name']}: {w}" for p in piles for w in p["warnings"]],
        "options": {"base": options.base, "density": options.density, "cell": options.cell},
    }


def _tonnes(piles: list[dict]) -> float | None:
    """The piles' tonnes summed when every pile has them."""
    tonnes = [p["tonnes"] for p in piles]
    return round(sum(tonnes), 3) if tonnes and None not in tonnes else None


def _write(folder, report: dict, inventory: Inventory, pile_survey: Survey) -> None:
    """The four outputs into the staging folder (committed together by :func:`output_dir`)."""
    if inventory.piles:
        write_gpkg(folder.path("piles.gpkg"), inventory, pile_survey.grid)
    write_csv(folder.path("piles.csv"), inventory)
    write_html(folder.path("report.html"), report, map_png(pile_survey, inventory))
    folder.path("report.json").write_text(json.dumps(report, indent=2), encoding="utf-8")
