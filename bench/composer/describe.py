"""What a composed site was, in words: for reports of the population's worst sites."""

from __future__ import annotations


def _obj(o: dict) -> str:
    if o["kind"] == "water":
        return f"water {o['depth_m']:.1f} m deep in work {o['work'] + 1}"
    s = o["after"] or o["before"]
    size = (
        f"{2 * s['a']:.0f}x{2 * s['b']:.0f}x{s['h']:.1f} m" if s["shape"] not in ("bush", "tree") else f"{s['h']:.1f} m"
    )
    return f"{o['kind']} {size} {o['role']}"


def describe(desc: dict) -> str:
    """One line: terrain, works (kind, m3), objects (kind, size, role), sensors, georeferencing, coverage."""
    t = desc["terrain"]
    terrain = t["kind"] + (f" {t['slope_deg']:.0f} deg" if t["slope_deg"] else "")
    works = ", ".join(
        f"{w['kind']} {w['size']['volume_m3']:.0f} m3 ({w['size']['height_m']:.1f} m)" for w in desc["works"]
    )
    objects = ", ".join(_obj(o) for o in desc["objects"]) or "nothing"
    b, a = desc["sensors"]
    sensors = f"{b['kind']} {b['density']:.0f} -> {a['kind']} {a['density']:.0f} pts/m2"
    cov = desc["coverage"]
    coverage = f"overlap {cov['overlap']:.0%}, {sum(cov['holes'])} holes"
    return f"{terrain}; works: {works or 'none'}; not soil: {objects}; {sensors}; {desc['georef']['kind']}; {coverage}"


def kinds(desc: dict) -> list[str]:
    """Tags of what the site holds (terrain, works, objects by role, sensor pair, georeferencing,
    coverage), to group the population's errors by kind."""
    b, a = desc["sensors"]
    tags = [f"terrain: {desc['terrain']['kind']}", f"sensors: {b['kind']} -> {a['kind']}"]
    tags += [f"georef: {desc['georef']['kind']}"]
    tags += sorted({f"work: {w['kind']}" for w in desc["works"]})
    tags += sorted({f"object: {o['kind']} {o['role']}" for o in desc["objects"]})
    if desc["coverage"]["overlap"] < 1.0:
        tags.append("coverage: partial overlap")
    return tags
