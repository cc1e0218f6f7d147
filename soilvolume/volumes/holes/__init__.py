"""Hole filling, in one place: the interpolants (:mod:`.interpolate`, their solve
:mod:`.solve`), their error measured on known ground (:mod:`.testholes`), a survey's own holes
filled where the other sees change across them (:mod:`.epochfill`), holes across the outline of
the works (:mod:`.outline`) and the change no survey saw under a hole (:mod:`.blind`)."""
