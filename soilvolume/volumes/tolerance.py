"""What "reliable" promises: each 95 % interval within a surveyor's tolerance of the volume moved (cut + fill);
an interval wider than that is said, with its largest part in m³ (:func:`tolerance_check`)."""

from __future__ import annotations

from .uncertainty import TERMS, z_value

#: what "reliable" promises: the 95 % interval within these shares of the volume moved (cut + fill)
TOLERANCE = {"net": 0.01, "cut": 0.03, "fill": 0.03}
#: the interval's one-sigma terms (:data:`~.uncertainty.TERMS`) in words
WORDS = dict(
    zip(
        TERMS,
        (
            "the surveys' measurement noise over the change",
            "heights interpolated into holes",
            "the interpolation's error",
            "the bias correction's leftover",
            "the other terms",
        ),
        strict=True,
    )
)
#: the other terms' named parts (report.json ``uncertainty``, one-sigma m³ per part) in words: named in its stead
EXTRAS = {
    "skirt_m3": "change at the works' edges under the detection level",
    "broad_m3": "change spread wide under the detection level, away from the works",
    "outline_m3": "holes across the works' outlines",
    "marginal_detections_m3": "small change areas that may be noise",
    "registration_m3": "the registration's uncertainty",
    "statistic_m3": "the cells' height statistic",
    "classification_m3": "what is not soil, left out or counted",
}
BOUND = "change that could not be classified as soil or not, or seen"  # the bounds added as they are
STRIPS = "the flight strips' steps taken out (a cell given another strip's level)"


def moved_m3(report: dict) -> float:
    """The volume moved (cut + fill, m³) of a report: what the tolerances are shares of."""
    v = report.get("volume_m3") or {}
    return v.get("cut", 0.0) + v.get("fill", 0.0)


def past_net_tolerance(m3: float, moved: float) -> bool:
    """Whether ``m3`` could move the net past its tolerance (:data:`TOLERANCE` of the volume ``moved``)."""
    return m3 > TOLERANCE["net"] * moved


def tolerance_check(report: dict) -> list[tuple[str, str]]:
    """A caution when a 95 % interval is wider than :data:`TOLERANCE` of the volume moved, naming its largest part."""
    u, model, moved = report["uncertainty_m3"], report.get("uncertainty") or {}, moved_m3(report)
    wide = [q for q in TOLERANCE if u.get(q, 0.0) > TOLERANCE[q] * moved]
    if not wide:
        return []
    q = wide[0]
    bound = sum(float(((report.get(key) or {}).get("bound_m3") or {}).get(q, 0.0)) for key in ("excluded", "blind"))
    extras = {EXTRAS[k]: abs(float((model.get(k) or {}).get(q, 0.0))) for k in EXTRAS}
    strips = {STRIPS: abs(float((model.get("strips_m3") or {}).get(q, 0.0)))}
    terms, confidence = (model.get("terms_m3") or {}).get(q) or [], model.get("confidence", 0.95)
    name, m3 = largest_part(terms, confidence, bound, extras, strips)
    said = (
        f"the {q}'s 95 % interval (±{u[q]:,.1f} m³) is wider than {100 * TOLERANCE[q]:.0f} % of the volume moved "
        f"({moved:,.0f} m³): the {q} may be off by more than that; its largest part is {name} (±{m3:,.1f} m³)"
    )
    return [("caution", said)]


def largest_part(
    sigmas: list[float], confidence: float, bound: float, extras: dict | None = None, bounds: dict | None = None
) -> tuple[str, float]:
    """(words, m³ at ``confidence``) of the largest of an interval's one-sigma ``sigmas`` (in the order of
    :data:`~.uncertainty.TERMS`; the last, the other terms, by its named parts ``extras`` when given: words to
    one-sigma m³), its ``bound`` of change that could not be classified or seen and its other ``bounds`` (words to
    m³ as they are)."""
    z = z_value(confidence)
    parts = [(WORDS[term], z * float(x)) for term, x in zip(TERMS, sigmas, strict=False)]
    if extras and len(parts) == len(TERMS):
        parts[-1:] = [(words, z * m3) for words, m3 in extras.items()]
    return max([*parts, (BOUND, float(bound)), *(bounds or {}).items()], key=lambda p: p[1])
