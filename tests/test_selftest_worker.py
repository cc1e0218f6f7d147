"""The install's self-test covers what only runs off Linux: the CSF ground filter imports, and a
Dask worker started by ``spawn`` (as every worker is on Windows and macOS) runs an engine task."""

from __future__ import annotations

from soilvolume.scenes import selftest


def test_the_selftest_imports_csf_and_runs_a_spawned_dask_worker(tmp_path):
    assert "CSF" in selftest.check_imports()
    seconds = selftest.check_spawned_worker(tmp_path)
    assert 0 < seconds < 120
