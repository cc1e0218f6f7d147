"""Imported last by the local cluster's forkserver: what it imported is moved to the collector's permanent
generation, so no collection in a worker forked from it walks those objects again nor writes their pages."""

import gc

gc.freeze()
