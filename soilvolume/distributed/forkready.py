"""Imported last by the local cluster's forkserver (after :mod:`.forkpause` and the modules it
preloads): the garbage collector restarts with the imported objects frozen, so no collection in
the server or in a worker forked from it walks them again (nor touches their pages: copy-on-write
keeps them shared with the server); the extras :mod:`.forkpause` hid are importable again, and
YAML is parsed as before."""

from ..core import leanimport
from ..core.collector import resume
from .forkpause import HIDDEN, YAML

resume()
leanimport.unhide(HIDDEN)
leanimport.yaml_restored(YAML)
