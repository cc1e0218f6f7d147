"""What "reliable" promises: each 95 % interval within a surveyor's tolerance of the volume moved (cut + fill);
an interval wider than that is said, with its largest part in m³ (:func:`tolerance_check`)."""

from __future__ import annotations

from .uncertainty import z_value

#: what "reliable" promises: the 95 % interval within these shares of the volume moved (cut + fill)
TOLERANCE = {"net": 0.01, "cut": 0.03, "fill": 0.03}
#: the interval's parts in words: uncertainty.TERMS in order, then the bounds added as they are
PARTS = (
    "the surveys' measurement noise over the change",
    "heights interpolated into holes",
    "the interpolation's error",
    "the bias correction's leftover",
    "what is not soil, left out or counted",
)


def tolerance_check(v: dict, u: dict, model: dict, bound: float) -> list[tuple[str, str]]:
    """A caution when a 95 % interval is wider than :data:`TOLERANCE` of the volume moved, naming its largest part."""
    moved = v.get("cut", 0.0) + v.get("fill", 0.0)
    wide = [q for q in TOLERANCE if u.get(q, 0.0) > TOLERANCE[q] * moved]
    if not wide:
        return []
    q = wide[0]
    name, m3 = largest_part(model.get("terms_m3", {}).get(q) or [], model.get("confidence", 0.95), bound)
    said = (
        f"the {q}'s 95 % interval (±{u[q]:,.1f} m³) is wider than {100 * TOLERANCE[q]:.0f} % of the volume moved "
        f"({moved:,.0f} m³): the {q} may be off by more than that; its largest part is {name} (±{m3:,.1f} m³)"
    )
    return [("caution", said)]


def largest_part(sigmas: list[float], confidence: float, bound: float) -> tuple[str, float]:
    """(words, m³ at ``confidence``) of the largest of an interval's one-sigma ``sigmas`` (:data:`PARTS`) and its
    ``bound`` of change that could not be classified or seen."""
    z = z_value(confidence)
    parts = [(PARTS[k], z * float(x)) for k, x in enumerate(sigmas[: len(PARTS)])]
    parts.append(("change that could not be classified as soil or not, or seen", float(bound)))
    return max(parts, key=lambda p: p[1]) if parts else ("the measurement", 0.0)
