"""Imported first by the local cluster's forkserver (:data:`.cluster.FORKSERVER_PRELOAD`, which
takes module names only): Python's garbage collector is paused while the server imports Dask and
the tasks' modules (:mod:`soilvolume.core.collector`); :mod:`.forkready`, imported last, restarts
it with what they made frozen."""

from ..core.collector import pause

pause()
