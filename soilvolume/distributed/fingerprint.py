"""What a tiled run's kept tiles were computed from, so a resume never reuses work of other inputs,
options or code: every input file's content identity, every option that changes numbers (all not
declared run control in :class:`~soilvolume.options.Options`: a new one cannot be forgotten), the
engine's source and the run's plan (grid, registration, tiling)."""

from __future__ import annotations

import hashlib
import json
import os
import zlib
from dataclasses import fields
from functools import lru_cache
from pathlib import Path
from typing import Any

from ..inputs.vpc import read_vpc
from ..options import Options

WHOLE_BYTES = 16 * 2**20  # files up to this size are hashed whole
HEAD_BYTES = 64 * 1024  # else: the header and VLRs, the end (LAZ chunk table, EVLRs) ...
SAMPLES, SAMPLE_BYTES = 16, 4096  # ... and this many blocks spread over the body
FILE_OPTIONS = ("zones", "stable_mask")  # options naming files whose content matters


def file_identity(path: str | os.PathLike) -> dict[str, Any]:
    """Size, modification time (ns) and a CRC-32 of ``path``'s content (whole when small, else its
    first and last :data:`HEAD_BYTES` and :data:`SAMPLES` blocks between). A change detector:
    an edit in place keeps size and time only if set back, and the CRC still catches all but one
    in 4 billion; zlib's CRC reads 3-4 GB/s, BLAKE2 under 1 GB/s (a run hashes every tile)."""
    p = Path(path)
    st = p.stat()
    step = (st.st_size - 2 * HEAD_BYTES) // (SAMPLES + 1)
    samples = [(HEAD_BYTES + k * step, SAMPLE_BYTES) for k in range(1, SAMPLES + 1)]
    spans = (
        [(0, None)] if st.st_size <= WHOLE_BYTES else [(0, HEAD_BYTES), *samples, (st.st_size - HEAD_BYTES, HEAD_BYTES)]
    )
    crc = 0
    with open(p, "rb") as f:
        for at, size in spans:
            f.seek(at)
            crc = zlib.crc32(f.read(size), crc)
    return {"size": st.st_size, "mtime_ns": st.st_mtime_ns, "hash": f"crc32:{crc:08x}"}


def input_identity(path: str | os.PathLike) -> dict[str, Any]:
    """{file name: identity} of an input: the file, and for a VPC each of its tiles too."""
    p = Path(path)
    out = {str(p): file_identity(p)}
    if p.suffix.lower() == ".vpc":
        out.update({t.path: file_identity(t.path) for t in read_vpc(p).tiles})
    return out


def number_options(options: Options) -> dict[str, Any]:
    """Every option that changes the numbers (not ``run_control``), a file named by one as its identity."""
    out: dict[str, Any] = {}
    for f in fields(options):
        if f.metadata.get("run_control"):
            continue
        value = getattr(options, f.name)
        if f.name in FILE_OPTIONS and value:  # a vector file and its sidecars (a Shapefile's .dbf, ...), or a folder
            path = Path(value)
            files = path.iterdir() if path.is_dir() else (p for p in path.parent.iterdir() if p.stem == path.stem)
            value = {"path": str(value), "files": {p.name: file_identity(p) for p in sorted(files) if p.is_file()}}
        out[f.name] = value
    return out


@lru_cache(maxsize=1)
def code_identity() -> str:
    """A digest of the engine's Python sources (a changed engine computes other numbers)."""
    root = Path(__file__).resolve().parent.parent
    digest = hashlib.blake2b(digest_size=16)
    for source in sorted(root.rglob("*.py")):
        digest.update(str(source.relative_to(root)).encode())
        digest.update(source.read_bytes())
    return digest.hexdigest()


def run_parts(inputs: dict[str, Any], options: Options, plan: dict[str, Any]) -> dict[str, Any]:
    """What a run's tiles are computed from, as plain JSON values; ``inputs``: {"before": ...,
    "after": ...} of :func:`input_identity`."""
    parts = {"code": code_identity(), "inputs": inputs, "options": number_options(options), "plan": plan}
    plain = lambda v: v.tolist() if hasattr(v, "tolist") else str(v)  # noqa: E731 - numpy values as Python
    return json.loads(json.dumps(parts, default=plain))  # tuples as lists: JSON-comparable


def difference(old: dict[str, Any], new: dict[str, Any]) -> str:
    """Why the tiles of ``old`` parts cannot serve ``new`` ones, in a few words ("" when equal)."""
    if old.get("code") != new.get("code"):
        return "the engine's code changed"
    for role in ("before", "after"):
        a, b = old.get("inputs", {}).get(role, {}), new.get("inputs", {}).get(role, {})
        for name in b:
            if name not in a:
                return f"the {role} input is another set of files ({Path(name).name} is new)"
            if a[name] != b[name]:
                return f"{Path(name).name} changed (size, modification time or content)"
        if set(a) != set(b):
            return f"the {role} input is another set of files"
    o, n = old.get("options", {}), new.get("options", {})
    for key in n:
        if o.get(key) != n[key] and isinstance(n[key], dict) and isinstance(o.get(key), dict):
            return f"the --{key.replace('_', '-')} file {Path(n[key]['path']).name} changed"
        if o.get(key) != n[key]:
            return f"--{key.replace('_', '-')} differs ({_short(o.get(key))} then, {_short(n[key])} now)"
    if old.get("plan") != new.get("plan"):
        return "the registration, grid or tiling differs"
    return "" if old == new else "they were computed differently"


def _short(value: Any) -> str:
    text = json.dumps(value) if isinstance(value, dict) else str(value)
    return text if len(text) <= 40 else text[:37] + "..."
