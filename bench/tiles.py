"""Split a LAS/LAZ file into square LAZ tiles and group them as a virtual point cloud (.vpc),
streaming (one chunk in memory), the way surveys are delivered."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from soilvolume.inputs.vpc import write_vpc  # noqa: E402


def split(src: Path, folder: Path, tile_m: float, chunk: int = 2_000_000) -> Path:
    """Write ``folder/<stem>_<i>_<j>.laz`` tiles of ``tile_m`` metres (aligned to multiples of
    ``tile_m``) and ``folder/<stem>.vpc`` with relative hrefs; returns the VPC path."""
    import laspy

    folder.mkdir(parents=True, exist_ok=True)
    writers: dict[tuple[int, int], laspy.LasWriter] = {}
    with laspy.open(str(src)) as reader:
        header = reader.header
        try:
            for pts in reader.chunk_iterator(chunk):
                i = np.floor(np.asarray(pts.x) / tile_m).astype(np.int64)
                j = np.floor(np.asarray(pts.y) / tile_m).astype(np.int64)
                key = i * 1_000_003 + j
                order = np.argsort(key, kind="stable")
                _, starts = np.unique(key[order], return_index=True)
                bounds = list(starts) + [len(order)]
                for a, b in zip(bounds[:-1], bounds[1:], strict=True):
                    idx = order[a:b]
                    t = (int(i[idx[0]]), int(j[idx[0]]))
                    if t not in writers:
                        h = laspy.LasHeader(point_format=header.point_format, version=header.version)
                        h.scales, h.offsets = header.scales, header.offsets
                        h.vlrs.extend(header.vlrs)
                        path = folder / f"{src.stem}_{t[0]}_{t[1]}.laz"
                        writers[t] = laspy.open(str(path), mode="w", header=h, do_compress=True)
                    writers[t].write_points(pts[idx])
        finally:
            for w in writers.values():
                w.close()
    tiles = sorted(folder.glob(f"{src.stem}_*.laz"))
    return write_vpc(folder / f"{src.stem}.vpc", tiles)


if __name__ == "__main__":
    print(split(Path(sys.argv[1]), Path(sys.argv[2]), float(sys.argv[3])))
