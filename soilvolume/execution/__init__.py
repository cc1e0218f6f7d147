"""Where a step's work runs (the execution seam): :mod:`.seam` the protocol and the typed results a
backend returns, :mod:`.inmemory` whole arrays in this process (threads beside), :mod:`.tiled` Dask
tasks over tiles of the grid. A backend holds no step of the method: the steps
(:mod:`soilvolume.workflow.steps`) hand it the work and it returns the merged result."""
