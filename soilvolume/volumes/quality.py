"""The quality gate: whether a run's volumes can be trusted, in plain words. Each check gives a
severity, ``caution`` (read the number with the reason in mind) or ``unreliable`` (do not use it as
it is), and a sentence; the verdict is the worst. The after survey's placement (``registration``) is
checked too, and a series' period by its two epochs' placements into E0's frame and its own figures."""

from __future__ import annotations

import numpy as np

from ..compensation.stable import largest_gap_deg
from ..core.record import QualityInputs
from ..core.wording import opt
from ..registration.georef import GROUND_AGREES, INCONCLUSIVE, disagreement
from .coverage import check as coverage_check
from .tolerance import moved_m3, past_net_tolerance, tolerance_check
from .zones import zone_messages

VERDICTS = ("reliable", "use with caution", "not reliable")
UNCLASSIFIED_SHARE = 0.1  # change that may not be soil over this share of the net (and its interval): said
OPEN_SHARE = 0.1  # change that may not be soil over this share of the volume moved: not reliable
CANOPY_SHARE = 0.05  # change under vegetation told by returns alone, over this share of the moved: not reliable
BLIND_SHARE = 0.02  # what holes in the works may hide, over this share of the volume moved: not reliable
MIN_STABLE_FRACTION = 0.05  # less stable ground than this share of the compared area: not reliable
LOW_STABLE_FRACTION = 0.1  # less than this: use with caution (a site whose works cover most of it)
MIN_STABLE_CELLS = 30
PRIOR_MARGIN = 0.8  # a pose using more than this share of the prior is suspicious


def assess(report: dict, q: QualityInputs) -> dict:
    """``{"verdict", "trusted", "messages"}`` for a finished run (see module)."""
    v, u = report["volume_m3"], report["uncertainty_m3"]
    out = registration_checks(report["registration"], q.stable, q.change, q.offset, q.prior, q.diff)
    out += correction_check(float(np.nansum(np.where(q.change, q.offset, 0.0)) * q.cell_area), v["net"], u["net"])
    excluded, hidden = report.get("excluded") or {}, report.get("blind") or {}
    bound = sum(float((r.get("bound_m3") or {}).get("net", 0.0)) for r in (excluded, hidden))
    random_half = max(u["net"] - bound, 0.0)  # the interval without what could not be classified or seen
    moved = max(moved_m3(report), 1e-9)
    out += _blind(hidden, moved) + _canopy(excluded, moved) + _unclassified(excluded, v["net"], random_half, moved)
    out += _nonsoil(excluded, random_half, u["net"])
    out += [("caution", m) for m in zone_messages(report.get("zones") or [])]
    out += filter(None, [coverage_check(report)])
    if all(sev != "unreliable" for sev, _ in out):  # a run not reliable states no confidence
        out += significance_check(v["net"], u["net"])
    if not out:  # reliable only with the interval within the tolerance
        out += tolerance_check(report)
    return verdict(out)


def correction_check(corr: float, net: float, half: float) -> list[tuple[str, str]]:
    """When the bias correction over the change areas (``corr`` m3) is comparable to the net, beyond ``half``."""
    size = max(abs(net), 1e-9)
    if abs(corr) <= 0.5 * size or abs(corr) <= half:
        return []
    said = f"the bias correction ({corr:+.1f} m³ over the change areas) is comparable to the net change ({net:+.1f} m³)"
    return [("unreliable" if abs(corr) > 2 * size else "caution", said)]


def significance_check(net: float, half: float) -> list[tuple[str, str]]:
    """A caution when the net lies within its 95 % interval of zero."""
    said = f"the net change ({net:+.1f} m³) is within its 95 % interval (±{half:.1f} m³) of zero: it is not significant"
    return [] if abs(net) > half else [("caution", said)]


def _nonsoil(excluded: dict, half: float, reported: float) -> list[tuple[str, str]]:
    """When what was excluded or flagged exceeds the measurement part ``half`` of the net's interval (a LAS
    classification not doubted)."""
    moved = excluded.get("moved_objects") or {}
    parts = [moved.get("fill", 0.0) + moved.get("cut", 0.0) if moved.get("excluded") else 0.0]
    if not excluded.get("by_classification"):
        parts += [abs(c.get("net", 0.0)) for c in (excluded.get("classes") or {}).values()]
    parts += [abs((excluded.get("rough") or {}).get("net", 0.0))]
    parts += [sum(abs(i.get("volume_m3", 0.0)) for i in (excluded.get("single_objects") or {}).get("items") or [])]
    if sum(parts) <= half:
        return []
    words = "; ".join(sentence(excluded))
    if half >= reported - 0.005:  # the reported interval is all measurement
        return [("caution", f"{words}: together more than the net's interval (±{reported:.2f} m³)")]
    said = (
        f"{words}: together more than the part of the net's interval (±{reported:.2f} m³) that is measurement "
        f"error (±{half:.2f} m³; the rest is change that could not be classified or seen)"
    )
    return [("caution", said)]


def _unclassified(excluded: dict, net: float, half: float, moved: float) -> list[tuple[str, str]]:
    """When the unclassified change exceeds the interval and :data:`UNCLASSIFIED_SHARE` of the net: unreliable without
    signals or over :data:`OPEN_SHARE` of the volume ``moved`` (the number may be off by that much); on a job that
    moved less than the interval's measurement part ``half``, over that part (no change is measured by its noise)."""
    u, bound = excluded.get("unclassified") or {}, float((excluded.get("bound_m3") or {}).get("net", 0.0))
    no_change = moved <= half  # a job that moved less than its noise is measured by it
    wide = bound > (half if no_change else OPEN_SHARE * moved)
    if bound <= max(half, UNCLASSIFIED_SHARE * abs(net)) and not wide:
        return []
    signals, n = u.get("signals", True), u.get("count", 0)
    below, above = u.get("net_range_m3") or (-u.get("fill", 0.0), u.get("cut", 0.0))
    said = (
        f"{u.get('fill', 0.0) + u.get('cut', 0.0):.0f} m³ of change in {n} compact object{'s' * (n != 1)} or "
        f"rough area{'s' * (n != 1)} could not be classified as soil or not ({_why(u, signals)}): the soil's net "
        f"lies anywhere from {net + below:+.0f} to {net + above:+.0f} m³, and the interval is widened by it"
    )
    if wide and no_change:
        said += f"; that is more than the measurement error (±{half:,.1f} m³) of a job that moved {moved:,.1f} m³"
    elif wide:
        said += f"; that is more than {OPEN_SHARE:.0%} of the volume moved ({moved:,.0f} m³)"
    return [("caution" if signals and not wide else "unreliable", said)]  # signals said the rest: only objects open


def _why(u: dict, signals: bool) -> str:
    """Why the unclassified change ``u`` could not be classified, its slab-like plates said with their m³."""
    if not signals:
        return "the files carry no classification, colour or return numbers to say what they are"
    plates, m3 = float(u.get("plates_m3", 0.0)), u.get("fill", 0.0) + u.get("cut", 0.0)
    slabs = "thin even plates with sharp edges: slabs, or a layer of soil"
    if plates < 0.5:
        return "these are machine-sized objects in one survey only"
    return slabs if plates >= m3 - 0.5 else f"machine-sized objects in one survey only, and {plates:,.0f} m³ of {slabs}"


def _canopy(excluded: dict, moved: float) -> list[tuple[str, str]]:
    """Change under vegetation told by returns alone: unreliable over :data:`CANOPY_SHARE` of the moved, caution over a
    fifth."""
    c = excluded.get("under_canopy") or {}
    reach = c.get("cut", 0.0) + c.get("fill", 0.0)
    if reach <= 0.2 * CANOPY_SHARE * moved or reach < 1.0:
        return []
    said = (
        f"{c.get('area_m2', 0.0):,.0f} m² of the change lies under vegetation that only return numbers "
        f"told apart (no classification): a dense canopy's single returns may be taken for ground there, "
        f"so up to {reach:,.0f} m³ of it may be vegetation; the interval is widened by it (a ground "
        f"classification, or {opt('ground', 'csf')}, measures the ground itself)"
    )
    return [("unreliable" if reach > CANOPY_SHARE * moved else "caution", said)]


def _blind(hidden: dict, moved: float) -> list[tuple[str, str]]:
    """Change on ground interpolated under a large hole, and holes without points in the works (:mod:`.holes.works`)
    whose range could move the net past its tolerance."""
    out, part = [], hidden.get("interpolated") or {}
    m3 = part.get("cut", 0.0) + part.get("fill", 0.0)
    if m3 > BLIND_SHARE * moved:
        said = (
            f"{m3:,.0f} m³ of the change ({part.get('area_m2', 0.0):,.0f} m²) stands where one survey saw no "
            "ground over a large area (vegetation or no returns): its ground there was interpolated from "
            "around it, and the volume carries that interpolation's error (in the interval)"
        )
        out.append(("unreliable", said))
    items = hidden.get("items") or []
    reach = float((hidden.get("bound_m3") or {}).get("net", 0.0))
    if not items or not past_net_tolerance(reach, moved):  # in the interval
        return out
    lo, hi = sum(min(i["range_m3"]) for i in items), sum(max(i["range_m3"]) for i in items)
    said = (
        f"{hidden['area_m2']:,.0f} m² inside the works has no point at all in the "
        f"{' and '.join(sorted({i['survey'] for i in items}))} survey ({len(items)} hole{'s' if len(items) > 1 else ''}"
        f": water, a shadow or no returns): the ground under it is unknown and the volume there adds anywhere from "
        f"{lo:+,.0f} to {hi:+,.0f} m³ to what is counted; the interval is widened by it"
    )
    return out + [("unreliable" if reach > BLIND_SHARE * moved else "caution", said)]


def verdict(found: list[tuple[str, str]]) -> dict:
    """The worst severity of ``found`` (severity, sentence) pairs in :data:`VERDICTS`' words, and the sentences."""
    worst = 2 if any(s == "unreliable" for s, _ in found) else 1 if found else 0
    messages = [m for _, m in found] or [
        "stable ground surrounds the works, the registration stays within "
        "the georeferencing prior and the net change is significant"
    ]
    return {"verdict": VERDICTS[worst], "trusted": worst == 0, "messages": messages}


def registration_checks(
    reg: dict, stable: np.ndarray, change: np.ndarray, offset: np.ndarray, prior: dict, diff: np.ndarray | None
) -> list[tuple[str, str]]:
    """A registered run's checks (stable ground, prior, fit) or a georeferenced one's."""
    used = reg.get("georeferencing", {}).get("used", "gps")
    if used == "gps":
        return _stable_checks(stable, change, offset) + _prior_checks(reg, prior)
    return _precise_checks(reg, stable, diff) if used == "precise" else []


def _stable_checks(stable: np.ndarray, change: np.ndarray, offset: np.ndarray) -> list[tuple[str, str]]:
    """Enough stable ground, and around the works."""
    n_stable, n_valid = int(stable.sum()), max(int(np.isfinite(offset).sum()), 1)
    share = n_stable / n_valid
    if n_stable < MIN_STABLE_CELLS or share < MIN_STABLE_FRACTION:
        said = f"too little stable ground ({share:.0%} of the compared area) to register the surveys and remove "
        return [("unreliable", said + "their bias: the works may have been absorbed")]
    if share < LOW_STABLE_FRACTION:
        said = f"little stable ground ({share:.0%} of the compared area): the registration and bias correction "
        return [("caution", said + "rest on it alone; check that they did not absorb the works")]
    if largest_gap_deg(stable, change) > 180:
        said = "the stable ground lies on one side of the works only: tilt and bias across the works are extrapolated"
        return [("caution", said)]
    return []


def _prior_checks(reg: dict, prior: dict) -> list[tuple[str, str]]:
    """The pose within the georeferencing prior, the fit of the after survey."""
    out: list[tuple[str, str]] = []
    for key, unit in (("rotation_deg", "deg"), ("tilt_deg", "deg"), ("shift_m", "m")):
        val, limit = reg.get(key, 0.0), prior[key.split("_")[0]]
        if limit > 0 and val > PRIOR_MARGIN * limit:
            said = f"the registration used {val:.2f} {unit} of a {limit:g} {unit} georeferencing prior"
            out.append(("caution", f"{said} ({key.split('_')[0]})"))
    if reg.get("fine", {}).get("poses_beyond_prior", 0) > 0:  # registration's count, not its wording
        said = "registration wanted a pose beyond the georeferencing prior (the works may pull it); the best pose"
        out.append(("caution", said + " within the prior was kept"))
    fit = reg.get("fine", {}).get("fitness")
    if fit is not None and np.isfinite(fit) and fit < 0.5:
        out.append(("caution", f"only {fit:.0%} of the after survey fits the before surface after registration"))
    return out


def _precise_checks(reg: dict, stable: np.ndarray, diff: np.ndarray | None) -> list:
    """A georeferenced run's: the ground outside the works agrees, the coordinates confirmed."""
    out: list[tuple[str, str]] = []
    check = (reg.get("georeferencing") or {}).get("check") or {}
    if check.get("outcome") == INCONCLUSIVE:
        said = (
            f"the registration could not confirm the files' coordinates ({disagreement(check)}): they were "
            "used as georeferenced because both declare one vertical datum and the after survey's margin agrees"
        )
        out.append(("caution", said))
    ground = diff[stable & np.isfinite(diff)] if diff is not None else np.empty(0)
    shift = float(np.median(ground)) if ground.size else 0.0
    if abs(shift) > GROUND_AGREES:
        said = (
            f"the ground outside the change areas differs by {shift:+.2f} m between the surveys and was not "
            f"corrected (coordinates used as georeferenced): check the datums, or use {opt('georeferencing', 'gps')}"
        )
        out.append(("caution", f"{said} if it is a survey offset"))
    return out


def sentence(report: dict) -> list[str]:
    """Plain sentences on what was excluded and listed (for the verdict and the CLI)."""
    out = []
    m = report.get("moved_objects") or {}
    if m.get("count"):
        verb = "excluded" if m.get("excluded") else f"counted ({opt('exclude', 'none')})"
        out.append(
            f"{m['fill']:.0f} m³ of apparent fill and {m['cut']:.0f} m³ of apparent cut in {m['count']} "
            f"moved object{'s' if m['count'] > 1 else ''} {verb}"
        )
    for name, part in (report.get("classes") or {}).items():
        if part["area_m2"] > 0 and abs(part["net"]) >= 0.5:
            out.append(f"{part['net']:+.0f} m³ of apparent change on {part['area_m2']:.0f} m² of {name} excluded")
    r, g = report.get("rough") or {}, report.get("grass_patches") or {}
    if r.get("area_m2") and abs(r.get("net", 0.0)) >= 0.5:
        out.append(
            f"{r['net']:+.0f} m³ of the change is on {r['area_m2']:.0f} m² of rough ground (vegetation?) and "
            "counted: no classification, colour or returns said what it is"
        )
    if g.get("area_m2") and abs(g.get("net", 0.0)) >= 0.5:
        out.append(
            f"{g['net']:+.0f} m³ of change on {g['area_m2']:.0f} m² of compact patches mostly of vegetation, with "
            "little soil measured in them, left out as grass"
        )
    u = report.get("unclassified") or {}
    if u.get("count") and u.get("fill", 0.0) + u.get("cut", 0.0) >= 0.5:
        out.append(
            f"{u['fill']:.0f} m³ of apparent fill and {u['cut']:.0f} m³ of apparent cut in {u['count']} compact "
            "objects or rough areas could not be classified (counted; the interval holds both readings)"
        )
    s = report.get("single_objects") or {}
    kept = [i for i in s.get("items") or [] if i.get("counted", s.get("counted", True))]
    left = [i for i in s.get("items") or [] if i not in kept]
    for group, words in (
        (left, f"left out as machines, containers or materials ({opt('objects', 'exclude')})"),
        (kept, "counted: check that they are soil"),
    ):
        if s.get("count") and group:
            m3 = sum(i["volume_m3"] * (1 if i["kind"] == "fill" else -1) for i in group)
            out.append(f"{len(group)} object{'s' if len(group) > 1 else ''} in one survey only ({m3:+.0f} m³) {words}")
    return out


def epoch_checks(registrations: list[dict], vols: list, prior: dict) -> list[list[tuple[str, str]]]:
    """Each epoch's placement checks (E0's none) in words naming it; ``vols[k - 1]``: the pair E0 -> Ek."""
    out: list[list[tuple[str, str]]] = [[]]
    for k, (reg, v) in enumerate(zip(registrations[1:], vols, strict=True), 1):
        found = registration_checks(reg, v.stable, v.change_mask, v.offset, prior, v.diff)
        out.append([(sev, f"E{k} in E0's frame: {said}") for sev, said in found])
    return out


def period_quality(change, checks: list[list[tuple[str, str]]], vols: list, cell_area: float) -> dict:
    """A series' period's verdict: its epochs' ``checks``, its own correction and significance."""
    i, j = change.start, change.end
    found = (checks[i] if i else []) + checks[j]
    offsets = [np.zeros_like(vols[0].offset)] + [v.offset for v in vols]
    corr = float(np.nansum(np.where(change.fill_area | change.cut_area, offsets[j] - offsets[i], 0.0)) * cell_area)
    net, half = change.volume["net"], change.uncertainty["net"]
    return verdict(found + correction_check(corr, net, half) + significance_check(net, half))
