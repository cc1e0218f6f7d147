"""Hole filling: the interpolants (:mod:`.interpolate`, :mod:`.solve`), their error (:mod:`.testholes`),
a survey's own holes (:mod:`.epochfill`), the outline's (:mod:`.outline`), the unseen (:mod:`.blind`)."""
