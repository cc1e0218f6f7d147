"""Imported first by the local cluster's forkserver (:data:`.cluster.FORKSERVER_PRELOAD`, which
takes module names only): Python's garbage collector is paused while the server imports Dask and
the tasks' modules (:mod:`soilvolume.core.collector`), the optional extras nothing of a worker
uses are hidden from them (:data:`soilvolume.core.leanimport.EXTRAS`: laspy's requests, Dask's
jinja2) and YAML is parsed by LibYAML; :mod:`.forkready`, imported last, restarts the collector
with what they made frozen and puts both back."""

from ..core import leanimport
from ..core.collector import pause

pause()
HIDDEN = leanimport.hide()
YAML = leanimport.yaml_on_libyaml()  # Dask's and Distributed's defaults parsed by LibYAML
