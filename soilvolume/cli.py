"""Command line: ``soilvolume estimate BEFORE AFTER --out DIR [options]`` and friends.

Options and their help come from :class:`soilvolume.options.Options`: ``--help`` explains every knob.
"""

from __future__ import annotations

import argparse
import json
import logging
import re
import sys
import traceback
from dataclasses import fields
from pathlib import Path

from .core import wording
from .core.interrupt import Interrupted, handle_signals
from .core.memlimit import out_of_memory, short_of_memory
from .core.nativelog import hold_native_stderr, quiet_library_warnings
from .core.outputs import os_problem
from .core.types import SoilVolumeError
from .options import Options, command_fields
from .protocol import Protocol, open_protocol
from .seriescli import add_series, cmd_series
from .validate import check_bounds, check_options

SKIP = {"keep_registered_cloud"}
EPILOG = """Outputs in DIR: dem_before.tif, dem_after.tif (average-height DEMs, refilled heights where
filled_mask.tif is 1), difference.tif (H_after - H_before - correction: dem_after - dem_before -
plane_offset), plane_offset.tif (the correction d_i), filled_mask.tif,
excluded.tif (what is not soil: vegetation, objects, moved objects; see --exclude),
report.json, report.html, and with --registered-cloud after_registered.laz.
change_areas.geojson: the areas of significant change as cut and fill polygons with their volumes.
Volumes are in cubic metres: fill = material added, cut = removed,
net = fill - cut. Lengths are metres in the before cloud's CRS (vertical feet are converted).
The outputs appear together or not at all; exit status 0 (done), 1 (error, one line on stderr),
2 (bad command line), 130/143 (interrupted by SIGINT/SIGTERM; nothing written)."""


def add_options(p: argparse.ArgumentParser, command: str) -> None:
    """One ``--flag`` per option ``command`` takes (``command_fields``; ``--registered-cloud`` is its own)."""
    for f in command_fields(command):
        if f.name in SKIP:
            continue
        flag = "--" + f.name.replace("_", "-")
        kind = {"float": float, "int": int, "float | None": float}.get(str(f.type), str)
        choices = f.metadata["choices"]
        p.add_argument(
            flag,
            dest=f.name,
            type=kind,
            choices=choices,
            default=None,
            help=f"{wording.cli(f.metadata['help'])} (default: {f.default})",
        )


def add_progress(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--progress",
        choices=("text", "jsonl"),
        default="text",
        help="text: progress lines on stderr for people; jsonl: one JSON object per line on stdout "
        "(progress, log, warning, error, result) for programs, and a line 'cancel' on stdin cancels",
    )


def options_from(ns: argparse.Namespace) -> Options:
    """The Options of the parsed flags, each checked against its allowed range."""
    given = {f.name: getattr(ns, f.name) for f in fields(Options) if getattr(ns, f.name, None) is not None}
    if getattr(ns, "registered_cloud", False):
        given["keep_registered_cloud"] = True
    return check_options(Options(**given))


class Parser(argparse.ArgumentParser):
    """argparse whose errors are one line and exit 2: ``soilvolume: error: --cell: invalid float
    value: 'abc'`` (its own usage block runs to 30 lines)."""

    def error(self, message: str):
        text = re.sub(r"^argument ([^:/ ]+)(/[^:]+)?: ", r"\1: ", message)
        self.exit(2, f"soilvolume: error: {one_line(text)}\n")


def build_parser() -> argparse.ArgumentParser:
    ap = Parser(
        prog="soilvolume",
        description="Soil volume change between two georeferenced point clouds (Shao et al. method, "
        "with robust registration and stable-ground correction).",
    )
    sub = ap.add_subparsers(dest="command", required=True)

    est = sub.add_parser(
        "estimate",
        help="the whole pipeline: register, grid, difference, volumes",
        description="Estimate the soil volume change from BEFORE to AFTER.",
        epilog=EPILOG,
    )
    est.add_argument(
        "before",
        type=Path,
        help="wide 'before' survey (LAS/LAZ, COPC, VPC of tiles, PLY/PCD/XYZ) or a design DEM GeoTIFF (.tif)",
    )
    est.add_argument("after", type=Path, help="smaller 'after' survey (the same formats)")
    est.add_argument(
        "--out", type=Path, required=True, help="output folder (created; must be empty unless --overwrite)"
    )
    est.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the output folder of an earlier run as a whole, in one swap (refused when it "
        "holds files a run does not write)",
    )
    est.add_argument(
        "--before-pipeline",
        type=Path,
        help="PDAL pipeline JSON preparing the before cloud (replaces reading it); its writers "
        "write into --out under their file names, never onto an input",
    )
    est.add_argument("--after-pipeline", type=Path, help="PDAL pipeline JSON preparing the after cloud")
    est.add_argument(
        "--registered-cloud",
        action="store_true",
        help="also write after_registered.laz, the after cloud moved by the registration (off by "
        "default: it costs as much as the rest of a large run; report.json has the 4x4 transform)",
    )
    est.add_argument("--quiet", action="store_true", help="no progress output")
    add_progress(est)
    add_options(est, "estimate")

    dem = sub.add_parser("dem", help="one cloud to an average-height GeoTIFF")
    dem.add_argument("cloud", type=Path, help="point cloud file")
    dem.add_argument("--out", type=Path, required=True, help="output GeoTIFF")
    dem.add_argument("--crs", help="CRS when the file has none")
    dem.add_argument(
        "--bounds",
        type=float,
        nargs=4,
        metavar=("XMIN", "YMIN", "XMAX", "YMAX"),
        help="grid extent in the cloud's CRS, or in --bounds-crs (snapped outwards to the cell)",
    )
    dem.add_argument("--bounds-crs", help="CRS of --bounds when it is not the cloud's (e.g. EPSG:4326)")
    add_progress(dem)
    add_options(dem, "dem")

    reg = sub.add_parser("register", help="register AFTER onto BEFORE and write it")
    reg.add_argument("before", type=Path)
    reg.add_argument("after", type=Path)
    reg.add_argument("--out", type=Path, required=True, help="registered after cloud (.las/.laz)")
    add_progress(reg)
    add_options(reg, "register")

    vol = sub.add_parser("volume", help="cut/fill/net between two DEM GeoTIFFs (optional zones)")
    vol.add_argument("before_dem", type=Path)
    vol.add_argument("after_dem", type=Path)
    vol.add_argument("--out", type=Path, required=True, help="difference GeoTIFF to write")
    vol.add_argument("--zones", type=Path, help="polygon file (GeoPackage/Shapefile/GeoJSON)")
    vol.add_argument("--zone-field", help="attribute naming each zone")
    add_progress(vol)

    add_series(sub, add_options, add_progress)
    add_tools(sub)
    return ap


def add_tools(sub) -> None:
    """The sub-commands around the method: pipeline, demo, selftest."""
    pipe = sub.add_parser(
        "pipeline",
        help="write the PDAL pipelines that prepare both clouds",
        description="Write before.json and after.json: read, reproject to the before CRS, crop the before "
        "cloud to the after footprint + radius, ground, outliers; run them with `pdal pipeline` or pass "
        "them to `soilvolume estimate --before-pipeline/--after-pipeline`.",
    )
    pipe.add_argument("before", type=Path)
    pipe.add_argument("after", type=Path)
    pipe.add_argument("--emit", type=Path, required=True, help="folder for the two pipeline JSON files")
    add_options(pipe, "pipeline")

    demo = sub.add_parser("demo", help="make a seeded synthetic pair with known volumes and run it")
    demo.add_argument("--out", type=Path, default=Path("demo_out"), help="folder for the pair and results")
    demo.add_argument("--size", choices=("small", "paper"), default="small", help="scene size")
    demo.add_argument("--seed", type=int, default=0, help="scene seed")

    check = sub.add_parser(
        "selftest",
        help="check this installation: every dependency imports, a tiny seeded pair is estimated",
        description="Import every dependency, write a seeded pair of a few thousand points (LAZ) "
        "and estimate it; exit 0 when the volumes are where they must be.",
    )
    check.add_argument("--out", type=Path, required=True, help="folder for the pair and its results")
    add_progress(check)


def _hooks(ns: argparse.Namespace):
    """The protocol's progress, log and cancel; else progress for people on stderr where the command has
    ``--quiet`` (the estimate) and it is not given; else none (dem, register, volume print only JSON)."""
    from .api import Hooks

    proto: Protocol | None = getattr(ns, "protocol", None)
    if proto is not None:
        return Hooks(progress=proto.progress, log=proto.log, cancel=proto.is_cancelled, keyed=True)
    if getattr(ns, "quiet", True):
        return Hooks()

    def show(pct: float, msg: str) -> None:
        print(f"[{pct:5.1f}%] {msg}", file=sys.stderr, flush=True)

    return Hooks(progress=show)


def _result(ns: argparse.Namespace, **data) -> bool:
    """Send a command's result as the protocol's last line; False without the protocol."""
    proto: Protocol | None = getattr(ns, "protocol", None)
    if proto is None:
        return False
    proto.emit("result", command=ns.command, **data)
    return True


def cmd_estimate(ns: argparse.Namespace) -> int:
    from .api import estimate
    from .reporting.report import summary_lines

    res = estimate(
        ns.before,
        ns.after,
        ns.out,
        options_from(ns),
        overwrite=ns.overwrite,
        hooks=_hooks(ns),
        before_pipeline=ns.before_pipeline,
        after_pipeline=ns.after_pipeline,
    )
    if _result(ns, report=res.report, outputs=res.outputs, summary=front_end_summary(res.keyed or res.report)):
        return 0
    for line in summary_lines(res.report):
        print(line)
    print(f"outputs in {ns.out}")
    return 0


def front_end_summary(report: dict) -> dict:
    """The figures a front end shows beside report.json: rotation and shift, the verdict, the
    significance in words (each zone's ± is in report.json's zones)."""
    from .reporting import summary

    local = (report.get("registration") or {}).get("transform_local")
    return {
        **(summary.rotation_shift(local) if local is not None else {}),
        "quality": summary.quality(report),
        "significance": summary.significance(report),
    }


def cmd_dem(ns: argparse.Namespace) -> int:
    from .api import cloud_to_dem

    options, bounds = options_from(ns), check_bounds(ns.bounds)
    if bounds is not None and ns.bounds_crs:
        bounds = bounds_in_cloud_crs(ns.cloud, ns.crs, bounds, ns.bounds_crs)
    info = cloud_to_dem(ns.cloud, ns.out, options, crs=ns.crs, bounds=bounds, hooks=_hooks(ns))
    if not _result(ns, **info):
        print(json.dumps(info, indent=2))
    return 0


def bounds_in_cloud_crs(cloud: Path, crs: str | None, bounds: tuple, bounds_crs: str) -> tuple:
    """``bounds`` (in ``bounds_crs``) as the box around them in the cloud's CRS (``crs`` when
    given, else its header's); unchanged when the cloud has no CRS."""
    import pyproj

    from .inputs.crs import parse_crs
    from .inputs.stream import open_source

    wkt = crs or open_source(cloud).crs_wkt
    if not wkt:
        return bounds
    to = pyproj.Transformer.from_crs(parse_crs(bounds_crs, "--bounds-crs"), parse_crs(wkt, str(cloud)), always_xy=True)
    return check_bounds(to.transform_bounds(*bounds))


def cmd_register(ns: argparse.Namespace) -> int:
    from .api import register

    res = register(ns.before, ns.after, ns.out, options_from(ns), hooks=_hooks(ns))
    if not _result(ns, **res):
        print(json.dumps(res, indent=2))
    return 0


def cmd_volume(ns: argparse.Namespace) -> int:
    from .api import volume_from_rasters

    res = volume_from_rasters(
        ns.before_dem, ns.after_dem, ns.out, zones=ns.zones, zone_field=ns.zone_field, hooks=_hooks(ns)
    )
    if not _result(ns, **res):
        print(json.dumps(res, indent=2))
    return 0


def cmd_selftest(ns: argparse.Namespace) -> int:
    from .scenes.selftest import run_selftest

    res = run_selftest(ns.out, _hooks(ns))
    if not _result(ns, **res):
        print(json.dumps(res, indent=2))
    return 0


def cmd_pipeline(ns: argparse.Namespace) -> int:
    from .pipelines.emit import emit_pipelines

    for path in emit_pipelines(ns.before, ns.after, ns.emit, options_from(ns)):
        print(path)
    return 0


def cmd_demo(ns: argparse.Namespace) -> int:
    from .scenes.demo import run_demo

    return run_demo(ns.out, ns.size, ns.seed)


COMMANDS = {
    "estimate": cmd_estimate,
    "dem": cmd_dem,
    "register": cmd_register,
    "volume": cmd_volume,
    "demo": cmd_demo,
    "pipeline": cmd_pipeline,
    "selftest": cmd_selftest,
    "series": lambda ns: cmd_series(ns, options_from(ns), _hooks(ns), _result),
}


def _fail(message: str, code: int = 1, exc: BaseException | None = None) -> int:
    text = one_line(message)
    if _PROTOCOL:  # the message with its options by key (wording.opt), for the front end to word
        fields = {"field": getattr(exc, "field", None), "reason": getattr(exc, "reason", None)}
        keyed = one_line(exc.keyed) if isinstance(exc, SoilVolumeError) else text
        _PROTOCOL[0].emit("error", message=keyed, exit=code, **{k: v for k, v in fields.items() if v})
    print(f"soilvolume: error: {text}", file=sys.stderr)
    return code


_PROTOCOL: list[Protocol] = []  # the run's protocol, while one runs


def one_line(message: str, limit: int = 400) -> str:
    """A message on one line of at most ``limit`` characters."""
    text = " ".join(str(message).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def main(argv: list[str] | None = None) -> int:
    """Run one command; every failure is one line on stderr and a non-zero exit: 1 for errors,
    130/143 for SIGINT/SIGTERM (outputs are never half-written)."""
    logging.getLogger("rasterio").addHandler(logging.NullHandler())  # GDAL's errors reach us as exceptions
    quiet_library_warnings()
    with handle_signals(then_ignore=argv is None):  # None: the program exits right after
        ns = build_parser().parse_args(argv)
        ns.protocol = open_protocol() if getattr(ns, "progress", "text") == "jsonl" else None
        _PROTOCOL[:] = [ns.protocol] if ns.protocol else []
        with hold_native_stderr():  # dropped: no library's message unasked (SOILVOLUME_DEBUG=1 shows them)
            return _run(ns)


def _run(ns: argparse.Namespace) -> int:
    try:
        return COMMANDS[ns.command](ns)
    except Interrupted as exc:
        return _fail(str(exc), exc.exit_code, exc)
    except SoilVolumeError as exc:
        return _fail(str(exc), exc=exc)
    except OSError as exc:
        return _fail(str(os_problem(exc)))
    except MemoryError:
        return _fail(out_of_memory(), exc=SoilVolumeError(out_of_memory(keyed=True)))
    except RecursionError:
        return _fail("input nested too deeply")
    except KeyboardInterrupt:  # a signal arrived before the handlers were installed
        return _fail("interrupted", 130)
    except Exception as exc:  # a bug: for a program reading the protocol, an error line too
        if short_of_memory(exc):  # a library that cannot be mapped under ulimit -v
            return _fail(out_of_memory(), exc=SoilVolumeError(out_of_memory(keyed=True)))
        if not _PROTOCOL:
            raise
        traceback.print_exc()
        return _fail(f"internal error ({type(exc).__name__}: {exc}); please report it with the lines above", 1)


if __name__ == "__main__":
    sys.exit(main())
