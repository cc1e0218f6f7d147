"""The inputs of the hostile-input corpus (:mod:`test_hostile_corpus`): a small seeded pair as LAS
files and as virtual point clouds of quadrant tiles, broken VPCs, surveys with gaps, zone and
stable-ground files of every kind of wrong, and servers that accept a connection and then never
answer, or answer garbage. Everything is written once into one folder the cases only read."""

from __future__ import annotations

import copy
import json
import os
import shutil
import socket
import threading
import warnings
from pathlib import Path

import laspy
import numpy as np
from conftest import write_scene

from soilvolume.inputs.io import write_las
from soilvolume.inputs.vpc import write_vpc

UTM = "EPSG:32654"
SITE = (500060.0, 3900070.0, 500080.0, 3900100.0)  # a box on pile A of seed 3's after footprint
FAR = (510000.0, 3910000.0, 510050.0, 3910050.0)  # 14 km away


def quadrants(src: Path, folder: Path, name: str) -> Path:
    """``src`` split into four quadrant LAZ tiles under ``folder/name/`` and a VPC of them."""
    las = laspy.read(src)
    xyz, cls = np.c_[las.x, las.y, las.z], np.asarray(las.classification)
    mid = np.median(xyz[:, :2], axis=0)
    (folder / name).mkdir()
    parts = []
    for k, (east, north) in enumerate([(0, 0), (1, 0), (0, 1), (1, 1)]):
        m = ((xyz[:, 0] >= mid[0]) == bool(east)) & ((xyz[:, 1] >= mid[1]) == bool(north))
        parts.append(folder / name / f"{name}_{k}.laz")
        write_las(parts[-1], xyz[m], las.header.parse_crs().to_wkt(), cls[m])
    return write_vpc(folder / f"{name}.vpc", parts)


def _without(src: Path, dst: Path, box) -> None:
    """``src`` without its points inside the x/y ``box``."""
    las = laspy.read(src)
    xyz, cls = np.c_[las.x, las.y, las.z], np.asarray(las.classification)
    m = ~((xyz[:, 0] > box[0]) & (xyz[:, 0] < box[2]) & (xyz[:, 1] > box[1]) & (xyz[:, 1] < box[3]))
    write_las(dst, xyz[m], las.header.parse_crs().to_wkt(), cls[m])


def _box(b):
    x0, y0, x1, y1 = b
    return [[[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]]


def _geojson(path: Path, features: list, crs: str | None = UTM) -> None:
    doc = {"type": "FeatureCollection", "features": features}
    if crs:
        doc["crs"] = {"type": "name", "properties": {"name": crs}}
    path.write_text(json.dumps(doc))


def _zone(name: str, coords, kind: str = "Polygon") -> dict:
    return {"type": "Feature", "properties": {"name": name}, "geometry": {"type": kind, "coordinates": coords}}


def _shapefile_without_crs(path: Path, boxes) -> None:
    import shapely
    from pyogrio import raw

    geoms = np.array([shapely.to_wkb(shapely.Polygon(b[0])) for b in boxes], dtype=object)
    names = np.array([f"zone {k}" for k in range(len(boxes))], dtype=object)
    with warnings.catch_warnings():  # no CRS: the point of this file
        warnings.simplefilter("ignore")
        raw.write(str(path), geoms, [names], ["name"], driver="ESRI Shapefile", geometry_type="Polygon", crs=None)


def bad_vpcs(folder: Path, good: Path) -> None:
    """VPCs whose structure, boxes or hrefs are wrong, next to ``good``."""
    doc = json.loads(good.read_text())

    def variant(name: str, change) -> None:
        d = copy.deepcopy(doc)
        d = change(d) or d
        (folder / f"{name}.vpc").write_text(d if isinstance(d, str) else json.dumps(d))

    def set_prop(k: int, key: str, value):
        return lambda d: d["features"][k]["properties"].__setitem__(key, value)

    def set_href(k: int, href: str):
        return lambda d: d["features"][k]["assets"]["data"].__setitem__("href", href)

    def shift(d):
        box = d["features"][3]["properties"]["proj:bbox"]
        box[0], box[3] = box[0] + 500, box[3] + 500

    def wgs84_only_shifted(d):
        for f in d["features"]:
            del f["properties"]["proj:bbox"]
        f = d["features"][2]["bbox"]
        f[0], f[3] = f[0] + 0.01, f[3] + 0.01

    variant("list", lambda d: [d])
    variant("feature_string", lambda d: d["features"].__setitem__(1, "tile"))
    variant("assets_list", lambda d: d["features"][0].__setitem__("assets", ["a.laz"]))
    variant("asset_string", lambda d: d["features"][0]["assets"].__setitem__("data", "a.laz"))
    variant("count_many", set_prop(2, "pc:count", "many"))
    variant("count_wrong", set_prop(1, "pc:count", 12))
    variant("bbox_string", set_prop(2, "proj:bbox", "1 2 3 4"))
    variant("bbox_three", set_prop(2, "proj:bbox", [1, 2, 3]))
    variant("wkt_garbage", set_prop(2, "proj:wkt2", "GARBAGE[]"))
    variant("epsg_string", set_prop(0, "proj:epsg", "32654"))
    variant("box_shifted", shift)
    variant("wgs84_shifted", wgs84_only_shifted)
    variant("lat_out_of_range", lambda d: d["features"][0].__setitem__("bbox", [0, 95, 1, 96]))
    variant("empty", lambda d: d.__setitem__("features", []))
    variant("duplicate", lambda d: d["features"].__setitem__(1, copy.deepcopy(d["features"][0])))
    variant("href_passwd", set_href(0, "/etc/passwd"))
    variant("href_passwd_laz", set_href(0, "secrets.laz"))
    variant("href_folder", set_href(0, "folder.laz"))
    variant("href_missing", set_href(0, "gone.laz"))
    variant("href_remote", set_href(0, "https://example.com/tile.laz"))
    variant("href_fifo", set_href(0, "pipe.laz"))
    variant("href_self", set_href(0, "list.vpc"))
    variant("nested", lambda d: "[" * 100_000 + "]" * 100_000)
    (folder / "binary.vpc").write_bytes(bytes(range(256)) * 4)
    shutil.copyfile("/etc/passwd", folder / "secrets.laz")
    (folder / "folder.laz").mkdir()
    os.mkfifo(folder / "pipe.laz")


def zone_files(folder: Path) -> None:
    """Zones and stable-ground polygons: good, outside, in a wrong CRS, without one, invalid."""
    _geojson(
        folder / "zones.geojson", [_zone("pile", _box(SITE)), _zone("pad", _box((500085, 3900050, 500105, 3900065)))]
    )
    _geojson(folder / "zones_partly_far.geojson", [_zone("pile", _box(SITE)), _zone("far", _box(FAR))])
    _geojson(folder / "zones_far.geojson", [_zone("far", _box(FAR))])
    bowtie = [[[SITE[0], SITE[1]], [SITE[2], SITE[3]], [SITE[2], SITE[1]], [SITE[0], SITE[3]], [SITE[0], SITE[1]]]]
    _geojson(folder / "zones_bowtie.geojson", [_zone("bowtie", bowtie)])
    _geojson(folder / "zones_declared_lonlat.geojson", [_zone("pile", _box(SITE))], crs="EPSG:4326")
    _geojson(folder / "zones_other_utm.geojson", [_zone("pile", _box(SITE))], crs="EPSG:32655")
    _geojson(folder / "zones_points.geojson", [_zone("p", [SITE[0], SITE[1]], "Point")])
    _geojson(
        folder / "zones_line.geojson", [_zone("flat", [[[SITE[0], SITE[1]], [SITE[2], SITE[3]], [SITE[0], SITE[1]]]])]
    )
    _shapefile_without_crs(folder / "zones_lonlat_nocrs.shp", [_box((138.99, 35.2, 139.0, 35.21))])
    (folder / "zones_garbage.gpkg").write_bytes(b"SQLite format 3\0" + bytes(200))
    os.mkfifo(folder / "zones_fifo.geojson")
    _geojson(folder / "stable_far.geojson", [_zone("quiet", _box(FAR))])


def write_inputs(folder: Path) -> Path:
    """Every input of the corpus in ``folder`` (returned)."""
    before, after, _ = write_scene(folder / "pair", 3)
    for name in ("before", "after"):
        shutil.move(folder / "pair" / f"{name}.las", folder / f"{name}.las")
    shutil.rmtree(folder / "pair")
    _without(before := folder / "before.las", folder / "before_gap.las", (500040, 3900075, 500125, 3900120))
    _without(before, folder / "before_half.las", (500080, 3899000, 501000, 3901000))
    _without(before, folder / "before_no_works.las", (500052, 3900052, 500112, 3900104))  # every pile and the pit
    good = quadrants(before, folder, "before")
    quadrants(folder / "after.las", folder, "after")
    bad_vpcs(folder, good)
    zone_files(folder)
    (folder / "pipeline.json").write_text(json.dumps([{"type": "readers.las", "filename": str(before)}]))
    return folder


class Server:
    """A TCP server on 127.0.0.1 that accepts connections and then stays silent, or answers
    garbage; closed with :meth:`close`."""

    def __init__(self, garbage: bool) -> None:
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(16)
        self.port = self.sock.getsockname()[1]
        self.garbage, self.conns, self.stop = garbage, [], threading.Event()
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self) -> None:
        while not self.stop.is_set():
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            self.conns.append(conn)
            if self.garbage:
                try:
                    conn.sendall(b"\xff" * 64 + b"HTTP/1.1 200 OK\r\n\r\nhello" * 10)
                except OSError:
                    pass

    def close(self) -> None:
        self.stop.set()
        self.sock.close()
        for c in self.conns:
            c.close()


def free_port() -> int:
    """A port nothing listens on (bound, then released)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]
