"""One grid planner and one cell rule (workflow/plan): the in-memory and the tiled backends pick
the same cell and grid for the same input; a tiled run holds no points and counts them from the
first pass's columns."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import write_scene

from soilvolume.core.hooks import Hooks
from soilvolume.core.outputs import output_dir
from soilvolume.core.types import survey
from soilvolume.distributed.schedule import parse
from soilvolume.execution.inmemory import InMemory
from soilvolume.execution.tiled import Tiled
from soilvolume.inputs.footprint import footprint
from soilvolume.inputs.prepare import prepare
from soilvolume.inputs.stream import open_source
from soilvolume.options import Options
from soilvolume.workflow import steps
from soilvolume.workflow.context import Context
from soilvolume.workflow.plan import given_cell, plan_grid, reference_cell

REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"


def _cells(before: Path, after: Path) -> tuple:
    """(cell, grid) of the in-memory reading and of the tiled one (thinned subsets only)."""
    out = []
    for full in (True, False):
        prep = prepare(open_source(before), open_source(after), Options(), full=full)
        assert bool(len(prep.before)) is full  # the tiled reading holds no points
        poly = footprint(prep.after_thin[:, :2])
        cell = reference_cell(prep, poly, Options())
        boxes = [(t[:, :2].min(axis=0), t[:, :2].max(axis=0)) for t in (prep.after_thin, prep.before_thin)]
        out.append((cell, plan_grid(cell, boxes, prep.origin, prep.frame, "no overlap")))
    return out


@pytest.mark.parametrize("seed", [0, 3, 7])
def test_both_backends_pick_the_same_cell_on_seeded_scenes(tmp_path, seed):
    before, after, _ = write_scene(tmp_path, seed=seed)
    (cell_m, grid_m), (cell_t, grid_t) = _cells(before, after)
    assert cell_m == cell_t and grid_m == grid_t


@pytest.mark.skipif(not (REAL / "autzen_bmx_2010.las").exists(), reason="real pairs not beside the checkout")
def test_both_backends_pick_the_same_cell_on_real_data():
    (cell_m, grid_m), (cell_t, grid_t) = _cells(REAL / "autzen_bmx_2010.las", REAL / "autzen_bmx_2023.las")
    assert cell_m == cell_t == 3.2 and grid_m == grid_t


def test_the_given_cell_wins():
    assert given_cell(Options(cell=1.5)) == 1.5 and given_cell(Options()) is None


def _heights_product(ctx: Context, backend) -> np.ndarray:
    """A new product, composed in the test from the method's steps without touching a backend:
    the after epoch's heights on the shared grid."""
    with backend.session(ctx):
        prep = steps.read(ctx, backend)
        reg, _ = steps.register(ctx, prep, backend.dense(prep))
        return steps.grid(ctx, backend, prep, reg).dems[0].heights


def test_a_new_product_is_a_composition_that_runs_on_both_backends(tmp_path):
    before, after, _ = write_scene(tmp_path)
    got = []
    for name, backend in (("memory", InMemory()), ("tiles", Tiled(parse("threads:2")))):
        with output_dir(tmp_path / name, [before, after], False) as out:
            epochs = (survey(before), survey(after))
            ctx = Context(epochs, Options(scheduler="threads:2"), Hooks(), ("prepare", "register", "grid"), out=out)
            got.append(_heights_product(ctx, backend))
    assert got[0].shape == got[1].shape and np.isfinite(got[0]).sum() > 100
    np.testing.assert_array_equal(np.isfinite(got[0]), np.isfinite(got[1]))
