"""Build the native kernels: ``python -m soilvolume.native.build [--out DIR] [--cc CC] [--quiet]``.

:data:`soilvolume.native.SOURCES` compiled into the one library :func:`soilvolume.native.library_name`
names (renamed into place when complete). Exit status 0 when the library is there, 1 when it could not be built."""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
from pathlib import Path

from . import HERE, SOURCES, library_name

#: -ffp-contract=off: no fused multiply-add (the numpy twins round every product)
FLAGS = ["-O2", "-std=c99", "-fPIC", "-shared", "-ffp-contract=off", "-fno-fast-math", "-Wall"]
COMPILE_S = 120.0  # at most this long for the compiler


def build(out: Path = HERE, cc: str | None = None) -> tuple[Path | None, str]:
    """(the library, what happened); (None, why) when it could not be built."""
    target = out / library_name()
    if target.is_file():
        return target, f"present: {target}"
    # ``cc`` (none when not on the PATH), else ``$CC`` or the first of cc, gcc, clang on the PATH
    names = [cc] if cc else [os.environ.get("CC"), "cc", "gcc", "clang"]
    tool = next((name for name in names if name and shutil.which(name.split()[0])), None)
    if tool is None:
        return None, "no C compiler (cc, gcc or clang) found: the engine runs its numpy path"
    out.mkdir(parents=True, exist_ok=True)
    tmp = out / f".{target.name}.{os.getpid()}.tmp"
    cmd = [*tool.split(), *FLAGS, "-o", str(tmp), *(str(p) for p in SOURCES if p.suffix == ".c"), "-lm"]
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=COMPILE_S)
        if done.returncode != 0 or not tmp.is_file():
            last = (done.stderr or done.stdout).strip().splitlines()[-3:]
            return None, f"{tool} failed: {' / '.join(last)}"
        os.replace(tmp, target)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return None, f"{tool} failed: {exc}"
    finally:
        tmp.unlink(missing_ok=True)
    return target, f"built: {target}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m soilvolume.native.build", description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=HERE, help="folder for the library (default: beside the sources)")
    parser.add_argument("--cc", help="the C compiler (default: $CC, cc, gcc or clang)")
    parser.add_argument("--quiet", action="store_true", help="print nothing when it is built or present")
    args = parser.parse_args(argv)
    path, note = build(args.out, args.cc)
    if path is None or not args.quiet:
        print(f"native kernels: {note}", file=sys.stderr if path is None else sys.stdout)
    return 0 if path is not None else 1


if __name__ == "__main__":
    sys.exit(main())
