"""First-run dependencies: checked once at plugin load, a message bar with an Install button, and
a real pip run (a tiny local wheel) into a private folder through QGIS's task manager."""

from __future__ import annotations

import base64
import hashlib
import sys
import time
import zipfile
from pathlib import Path

import pytest
from qgis.core import QgsApplication
from qgis.PyQt.QtWidgets import QPushButton

WHEEL_FILES = {
    "tinysv/__init__.py": "VALUE = 42\n",
    "tinysv-0.1.dist-info/METADATA": "Metadata-Version: 2.1\nName: tinysv\nVersion: 0.1\n",
    "tinysv-0.1.dist-info/WHEEL": "Wheel-Version: 1.0\nGenerator: test\nRoot-Is-Purelib: true\nTag: py3-none-any\n",
}


def make_wheel(folder: Path) -> Path:
    """A minimal valid pure-Python wheel (module ``tinysv``)."""
    path = folder / "tinysv-0.1-py3-none-any.whl"
    record = []
    with zipfile.ZipFile(path, "w") as wheel:
        for name, text in WHEEL_FILES.items():
            data = text.encode()
            digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
            record.append(f"{name},sha256={digest},{len(data)}")
            wheel.writestr(name, data)
        record.append("tinysv-0.1.dist-info/RECORD,,")
        wheel.writestr("tinysv-0.1.dist-info/RECORD", "\n".join(record) + "\n")
    return path


@pytest.fixture
def fresh_bar(plugin_package, monkeypatch, qgis_iface):
    from soilvolume_qgis.plugin.installer import DependencyBar

    monkeypatch.setattr(DependencyBar, "shown", False)
    bar = qgis_iface.messageBar()
    bar.clearWidgets()
    yield bar
    bar.clearWidgets()


def our_items(bar) -> list:
    return [item for item in bar.items() if item.title() == "Soil volume change"]


def load_plugin(plugin_package, qgis_iface):
    plugin = plugin_package.classFactory(qgis_iface)
    plugin.initGui()
    return plugin


def test_missing_dependency_shows_one_bar_with_install(plugin_package, qgis_iface, fresh_bar, monkeypatch):
    from soilvolume_qgis.plugin.installer import DependencyBar

    monkeypatch.setitem(sys.modules, "open3d", None)  # found nowhere
    calls = []
    monkeypatch.setattr(DependencyBar, "install", lambda self, reqs: calls.append(list(reqs)))
    load_plugin(plugin_package, qgis_iface).unload()  # a plugin reload: the bar is not repeated
    plugins = [load_plugin(plugin_package, qgis_iface)]
    try:
        items = our_items(fresh_bar)
        assert len(items) == 1 and "open3d" in items[0].text()
        button = items[0].findChild(QPushButton, "soilvolumeInstallDependencies")
        assert button is not None and button.text() == "Install"
        button.click()
        assert calls and any(r.startswith("open3d") for r in calls[0])
    finally:
        for plugin in plugins:
            plugin.unload()


def test_dask_is_optional_but_offered_with_the_rest(plugin_package, qgis_iface, fresh_bar, monkeypatch):
    """Without dask.distributed the plugin runs (no bar); when the bar shows for a required
    package, its Install button also installs dask[distributed]."""
    from soilvolume_qgis.plugin.installer import DependencyBar

    monkeypatch.setitem(sys.modules, "distributed", None)
    plugin = load_plugin(plugin_package, qgis_iface)
    try:
        assert our_items(fresh_bar) == []
    finally:
        plugin.unload()
    monkeypatch.setitem(sys.modules, "open3d", None)
    calls = []
    monkeypatch.setattr(DependencyBar, "install", lambda self, reqs: calls.append(list(reqs)))
    plugin = load_plugin(plugin_package, qgis_iface)
    try:
        our_items(fresh_bar)[0].findChild(QPushButton, "soilvolumeInstallDependencies").click()
        assert "dask[distributed]" in calls[0] and any(r.startswith("open3d") for r in calls[0])
    finally:
        plugin.unload()


def test_no_bar_when_everything_imports(plugin_package, qgis_iface, fresh_bar):
    plugin = load_plugin(plugin_package, qgis_iface)
    try:
        assert our_items(fresh_bar) == []
    finally:
        plugin.unload()


def test_install_runs_pip_into_the_private_folder(plugin_package, qgis_iface, fresh_bar, tmp_path, monkeypatch):
    from soilvolume_qgis.plugin import deps, installer

    target = tmp_path / "profile" / "soilvolume" / "site-packages"
    monkeypatch.setattr(deps, "site_dir", lambda: target)
    monkeypatch.setattr(sys, "path", list(sys.path))
    wheel = make_wheel(tmp_path)
    bar = installer.DependencyBar(qgis_iface)
    task = bar.install([str(wheel)])
    deadline = time.time() + 120
    while task.status() not in (task.Complete, task.Terminated) and time.time() < deadline:
        QgsApplication.processEvents()
        time.sleep(0.05)
    assert task.status() == task.Complete, "\n".join(task.lines)
    assert (target / "tinysv" / "__init__.py").is_file()
    assert str(target) in sys.path and sys.path.index(str(target)) > sys.path.index(str(Path(deps.__file__).parents[2]))
    import tinysv

    assert tinysv.VALUE == 42
    assert any("Successfully installed tinysv" in line for line in task.lines)
    assert task.progress() > 0
    command = task.commands[0]
    assert "--target" in command and "--user" not in command and "--break-system-packages" not in command
    sys.modules.pop("tinysv", None)


def test_pip_commands_keep_qgis_numpy(plugin_package, tmp_path):
    import numpy
    from soilvolume_qgis.plugin import deps

    commands = deps.pip_commands(["scipy", "open3d-cpu", "laspy[lazrs]"], tmp_path / "site-packages")
    first, second = commands
    assert "--no-deps" in second and second[-1] == "open3d-cpu"
    assert "dash" in first and "scipy" in first and "open3d-cpu" not in first
    constraints = Path(first[first.index("--constraint") + 1]).read_text()
    assert constraints.strip() == f"numpy=={numpy.__version__}"
