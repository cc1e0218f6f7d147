"""One module writes GeoTIFFs (soilvolume/dem/geotiff.py): no other engine module opens a raster
for writing, stages one in GDAL's memory or copies one with GDAL."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
WRITER = ROOT / "soilvolume" / "dem" / "geotiff.py"
DRIVERS = {"gtiff", "cog", "mem"}
WRITE_MODES = {"w", "w+", "r+"}


def _constant(node: ast.AST | None) -> str | None:
    return node.value if isinstance(node, ast.Constant) and isinstance(node.value, str) else None


def _rasterio_names(tree: ast.AST) -> set[str]:
    """The names rasterio goes by in a module (``import rasterio as rio`` included)."""
    names = {"rasterio"}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {a.asname for a in node.names if a.name == "rasterio" and a.asname}
    return names


def _writes(node: ast.Call, rasterio: set[str]) -> bool:
    """``rasterio.open(path, "w", ...)`` (or mode="w"/"w+"/"r+")."""
    func = node.func
    if not (isinstance(func, ast.Attribute) and func.attr == "open"):
        return False
    if not (isinstance(func.value, ast.Name) and func.value.id in rasterio):
        return False
    modes = [_constant(node.args[1])] if len(node.args) > 1 else []
    modes += [_constant(k.value) for k in node.keywords if k.arg == "mode"]
    return any(m in WRITE_MODES for m in modes)


def _gdal_driver(node: ast.AST) -> bool:
    """A GTiff / COG / MEM driver named as ``driver=`` or a ``"driver":`` entry."""
    if isinstance(node, ast.Call):
        return any(k.arg == "driver" and (_constant(k.value) or "").lower() in DRIVERS for k in node.keywords)
    if isinstance(node, ast.Dict):
        pairs = zip(node.keys, node.values, strict=True)
        return any(_constant(k) == "driver" and (_constant(v) or "").lower() in DRIVERS for k, v in pairs)
    return False


def geotiff_writes(path: Path) -> list[str]:
    """Where ``path`` writes a raster itself: ``line: what``."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    rasterio, found = _rasterio_names(tree), []
    for node in ast.walk(tree):
        line = getattr(node, "lineno", 0)
        if isinstance(node, ast.Call) and _writes(node, rasterio):
            found.append(f"{line}: rasterio.open for writing")
        if _gdal_driver(node):
            found.append(f"{line}: a GDAL driver for writing")
        if (isinstance(node, ast.Name) and node.id == "MemoryFile") or (
            isinstance(node, ast.Attribute) and node.attr == "MemoryFile"
        ):
            found.append(f"{line}: MemoryFile")
        if isinstance(node, ast.ImportFrom) and any(a.name == "MemoryFile" for a in node.names):
            found.append(f"{line}: MemoryFile")
        if isinstance(node, (ast.Import, ast.ImportFrom)) and "rasterio.shutil" in _imported(node):
            found.append(f"{line}: rasterio.shutil (GDAL's copy)")
    return sorted(found, key=lambda hit: int(hit.split(":")[0]))


def _imported(node: ast.Import | ast.ImportFrom) -> set[str]:
    if isinstance(node, ast.Import):
        return {a.name for a in node.names}
    return {node.module or ""} | {f"{node.module}.{a.name}" for a in node.names}


def test_one_module_writes_geotiffs():
    """Every GeoTIFF (a run's rasters, the tiled engine's COGs, the scenes' design
    surfaces) goes through dem/geotiff, where CRS, nodata, compression and the all-or-nothing
    full-disk handling live once."""
    hits = {
        str(p.relative_to(ROOT)): found
        for p in sorted((ROOT / "soilvolume").rglob("*.py"))
        if p != WRITER and (found := geotiff_writes(p))
    }
    assert hits == {}
    assert geotiff_writes(WRITER)  # the scan sees the writer's own writes


def test_the_scan_sees_every_way_of_writing_a_raster(tmp_path):
    probe = tmp_path / "probe.py"
    probe.write_text(
        "import rasterio as rio\nimport rasterio.shutil\nfrom rasterio.io import MemoryFile\n\n"
        "def f(p, profile):\n"
        "    rio.open(p, 'w', **profile)\n"
        "    rasterio.open(p, mode='r+')\n"
        "    profile.update({'driver': 'GTiff'})\n"
        "    mem_open(driver='COG')\n"
        "    rasterio.open(p)\n"
        "    open(p, 'w')\n"
    )
    found = geotiff_writes(probe)
    assert [f.split(":")[0] for f in found] == ["2", "3", "6", "7", "8", "9"], found
