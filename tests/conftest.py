"""Shared fixtures of the engine tests: seeded synthetic pairs written to disk, run once."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from soilvolume.api import estimate
from soilvolume.options import Options
from soilvolume.scenes.synthetic import SceneConfig, make_pair, write_pair

REAL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"
if not REAL.exists():
    REAL = Path("/work/shared/data/real")


#: the cluttered site of the soil tests: 80 x 78 m (after survey 40 x 37 m), ~40 points per m2, vehicles
#: resolved by 0.5 m cells; holes, outliers, doming, vegetation and objects
SITE = dict(
    before_size=(80.0, 78.0),
    after_size=(40.0, 37.0),
    before_points=250_000,
    after_points=150_000,
    noise_m=0.03,
    doming_m=0.02,
    outlier_fraction=0.003,
    holes=3,
    vegetation=True,
    objects=True,
)


def write_scene(folder: Path, seed: int = 0, **changes) -> tuple[Path, Path, dict]:
    cfg = replace(SceneConfig.small(), **changes)
    b, a, t = write_pair(make_pair(seed, cfg), folder)
    return b, a, json.loads(Path(t).read_text())


def run_python(code: str, timeout: float = 60) -> subprocess.CompletedProcess:
    """``code`` run by this Python in a fresh process (text output captured)."""
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout)


def run_cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """The console entry point as a user runs it (``python -m soilvolume``)."""
    return subprocess.run(
        [sys.executable, "-m", "soilvolume", *map(str, args)], cwd=cwd, capture_output=True, text=True, timeout=600
    )


@pytest.fixture
def alarm():
    """Fail instead of hanging for ever (a FIFO opened for reading blocks): 60 s."""
    import signal

    def timeout(*_):
        raise TimeoutError("hung for 60 s")

    old = signal.signal(signal.SIGALRM, timeout)
    signal.alarm(60)
    yield
    signal.alarm(0)
    signal.signal(signal.SIGALRM, old)


@pytest.fixture(scope="session")
def misaligned_pair(tmp_path_factory):
    """Known cut/fill, 2 m / 2 degree GPS misalignment (synthetic default), no bias."""
    return write_scene(tmp_path_factory.mktemp("misaligned"), 0)


@pytest.fixture(scope="session")
def misaligned_result(misaligned_pair, tmp_path_factory):
    before, after, truth = misaligned_pair
    out = tmp_path_factory.mktemp("misaligned_out") / "result"
    return estimate(before, after, out, Options()), truth, out


@pytest.fixture(scope="session")
def real_dir() -> Path:
    if not (REAL / "autzen_bmx_2010.las").exists():
        pytest.skip(f"real data not found in {REAL}")
    return REAL
