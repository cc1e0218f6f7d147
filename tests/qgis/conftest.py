"""Fixtures of the QGIS tests: the plugin imported as a package, Processing, a seeded scene.

pytest-qgis owns the QgsApplication (pitfalls 7 and 8 of the set-up notes). The plugin is imported
the way QGIS imports it: as a package named after its folder, here a symlink
``<tmp>/soilvolume_qgis -> <repo>``; the repository root itself must never be on ``sys.path``,
where its ``processing/`` folder would shadow QGIS's Processing framework.
"""

from __future__ import annotations

import atexit
import importlib
import os
import shutil
import sys
import tempfile
from pathlib import Path

import pytest
from qgis.core import QgsApplication

REPO = Path(__file__).resolve().parents[2]
# the engine's environment that `make setup` builds with the plugin's own installer
ENGINE_ENV = Path(os.environ.setdefault("SOILVOLUME_ENGINE_ENV", str(REPO / ".engine-env")))
PLUGIN_NAME = "soilvolume_qgis"
PROVIDER_ID = "soilvolume"
_KEEP_ALIVE: list = []  # Python wrappers of providers the registry owns


def _is_repo(entry: str) -> bool:
    try:
        return Path(entry or ".").resolve() == REPO
    except OSError:
        return False


def _sanitize_sys_path() -> None:
    """Drop the repo root from sys.path (``python -m pytest`` run from it puts it there) and any
    ``processing`` module imported from it; put QGIS's Python plugins folder first."""
    sys.path[:] = [entry for entry in sys.path if not _is_repo(entry)]
    shadow = sys.modules.get("processing")
    shadow_file = Path(getattr(shadow, "__file__", "") or "/").resolve()
    if shadow is not None and REPO in shadow_file.parents:
        for name in [n for n in sys.modules if n == "processing" or n.startswith("processing.")]:
            del sys.modules[name]
    qgis_plugins = str(Path(QgsApplication.pkgDataPath()) / "python" / "plugins")
    if qgis_plugins in sys.path:
        sys.path.remove(qgis_plugins)
    sys.path.insert(0, qgis_plugins)


LINK_PREFIX = "soilvolume-qgis-plugins-"


def _remove_stale_links() -> None:
    """Remove link folders of earlier sessions whose process is gone (killed or crashed before
    any clean-up could run); the folder name carries the process id."""
    for folder in Path(tempfile.gettempdir()).glob(f"{LINK_PREFIX}*-*"):
        pid = folder.name[len(LINK_PREFIX) :].split("-", 1)[0]
        if pid.isdigit() and not _alive(int(pid)):
            shutil.rmtree(folder, ignore_errors=True)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True  # exists, owned by someone else
    return True


def _link_plugin() -> Path:
    """A folder holding only ``soilvolume_qgis -> <repo>``, added to sys.path. Removed by the
    session fixture :func:`_remove_plugin_link` before QGIS exits (atexit as a fallback, and
    the next session removes it if this process is killed)."""
    _remove_stale_links()
    folder = Path(tempfile.mkdtemp(prefix=f"{LINK_PREFIX}{os.getpid()}-"))
    atexit.register(shutil.rmtree, folder, True)
    (folder / PLUGIN_NAME).symlink_to(REPO, target_is_directory=True)
    sys.path.append(str(folder))
    return folder


_sanitize_sys_path()
PLUGINS_DIR = _link_plugin()


@pytest.fixture(scope="session", autouse=True)
def _remove_plugin_link(qgis_app):
    """Remove the plugin link folder at the end of the session, before pytest-qgis tears the
    QgsApplication down: QGIS's exit can end the process before atexit handlers run."""
    yield
    shutil.rmtree(PLUGINS_DIR, ignore_errors=True)


@pytest.fixture(scope="session")
def plugin_package():
    """The plugin imported as QGIS imports it."""
    return importlib.import_module(PLUGIN_NAME)


@pytest.fixture(scope="session")
def plugins_dir() -> Path:
    return PLUGINS_DIR


@pytest.fixture(scope="session")
def plugin_zip(tmp_path_factory) -> Path:
    """The installable zip, as ``make package`` builds it."""
    import subprocess

    dist = tmp_path_factory.mktemp("dist")
    run = subprocess.run(
        ["bash", str(REPO / "scripts" / "package.sh")],
        cwd=REPO,
        env=dict(os.environ, DIST_DIR=str(dist)),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert run.returncode == 0, run.stderr
    return Path(run.stdout.strip().splitlines()[-1])


def ensure_provider():
    """The plugin's provider, registered in the Processing registry (again, when a test
    unloaded the plugin)."""
    from soilvolume_qgis.processing.provider import SoilVolumeProvider

    registry = QgsApplication.processingRegistry()
    existing = registry.providerById(PROVIDER_ID)
    if existing is None:
        existing = SoilVolumeProvider()
        _KEEP_ALIVE.append(existing)
        assert registry.addProvider(existing)
    return existing


@pytest.fixture
def provider(qgis_processing, plugin_package):
    return ensure_provider()


def run_algorithm(name: str, parameters: dict, context=None, feedback=None) -> dict:
    """``processing.run`` of one of the plugin's algorithms."""
    from qgis import processing
    from qgis.core import QgsProcessingFeedback

    ensure_provider()
    return processing.run(
        f"{PROVIDER_ID}:{name}", parameters, context=context, feedback=feedback or QgsProcessingFeedback()
    )


@pytest.fixture(scope="session")
def scene_dir(tmp_path_factory) -> Path:
    """A small seeded before/after pair (LAS with CRS) and its truth.json."""
    from soilvolume.scenes import synthetic

    folder = tmp_path_factory.mktemp("scene")
    scene = synthetic.make_pair(0, synthetic.SceneConfig.small())
    synthetic.write_pair(scene, folder)
    return folder


@pytest.fixture(scope="session")
def truth(scene_dir: Path) -> dict:
    import json

    return json.loads((scene_dir / "truth.json").read_text())


@pytest.fixture
def run_alg(qgis_processing, plugin_package):
    return run_algorithm


@pytest.fixture(scope="session")
def run_alg_session(qgis_processing, plugin_package):
    """:func:`run_algorithm` for module- or session-scoped fixtures."""
    return run_algorithm


@pytest.fixture(scope="session")
def estimate_inputs(scene_dir) -> dict:
    """The inputs and options of the reference estimate run on the seeded scene."""
    return {
        "BEFORE": str(scene_dir / "before.las"),
        "AFTER": str(scene_dir / "after.las"),
        "CELL": 1.0,
        "RADIUS": 30.0,
        "FINE": "icp",
        "CORRECTION": "surface",
    }


@pytest.fixture(scope="session")
def estimate_run(qgis_processing, plugin_package, estimate_inputs, tmp_path_factory) -> dict:
    """One full estimate through processing.run with every output written to files."""
    out = tmp_path_factory.mktemp("estimate")
    params = {
        **estimate_inputs,
        "DIFFERENCE": str(out / "difference.tif"),
        "DEM_BEFORE": str(out / "dem_before.tif"),
        "DEM_AFTER": str(out / "dem_after.tif"),
        "PLANE_OFFSET": str(out / "plane_offset.tif"),
        "FILLED_MASK": str(out / "filled_mask.tif"),
        "REGISTERED": str(out / "after_registered.laz"),
        "REPORT": str(out / "report.html"),
        "REPORT_JSON": str(out / "report.json"),
    }
    return run_algorithm("estimatevolumechange", params)


_RESTORED: list[bool] = []


def pytest_collectreport(report) -> None:
    """The engine tests do ``from conftest import ...`` meaning tests/conftest.py, but pytest's
    default import mode registered this file under that same module name. Once this folder is
    collected (this file imported), put a copy of the parent back under that name."""
    import importlib.util

    parent = REPO / "tests" / "conftest.py"
    if _RESTORED or not parent.is_file():
        return
    _RESTORED.append(True)
    if Path(getattr(sys.modules.get("conftest"), "__file__", "") or "/") == parent:
        return
    spec = importlib.util.spec_from_file_location("conftest", parent)
    if spec is None or spec.loader is None:
        return
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    sys.modules["conftest"] = module
