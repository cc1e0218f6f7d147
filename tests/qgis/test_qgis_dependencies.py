"""The engine's environment from the desktop: a message bar with an Install button at plugin
load when it is missing (once), none when it is ready, and the button running the same
installer as ``soilvolume:installdependencies`` (a background task that reports success only
after the engine's self-test passed)."""

from __future__ import annotations

import time

import pytest
from qgis.core import Qgis, QgsApplication
from qgis.PyQt.QtWidgets import QPushButton


@pytest.fixture
def fresh_bar(plugin_package, monkeypatch, qgis_iface):
    from soilvolume_qgis.plugin.installer import DependencyBar

    monkeypatch.setattr(DependencyBar, "shown", False)
    bar = qgis_iface.messageBar()
    bar.clearWidgets()
    bar.clear_messages()
    yield bar
    bar.clearWidgets()
    bar.clear_messages()


def our_items(bar) -> list:
    return [item for item in bar.items() if item.title() == "Soil volume change"]


def load_plugin(plugin_package, qgis_iface):
    plugin = plugin_package.classFactory(qgis_iface)
    plugin.initGui()
    return plugin


def test_missing_environment_shows_one_bar_with_install(plugin_package, qgis_iface, fresh_bar, monkeypatch, tmp_path):
    from soilvolume_qgis.plugin.installer import DependencyBar

    monkeypatch.setenv("SOILVOLUME_ENGINE_ENV", str(tmp_path / "nothing-here"))
    calls = []
    monkeypatch.setattr(DependencyBar, "install", lambda self, *a: calls.append(True))
    load_plugin(plugin_package, qgis_iface).unload()  # a plugin reload: the bar is not repeated
    plugin = load_plugin(plugin_package, qgis_iface)
    try:
        items = our_items(fresh_bar)
        assert len(items) == 1 and "not installed yet" in items[0].text()
        button = items[0].findChild(QPushButton, "soilvolumeInstallDependencies")
        assert button is not None and button.text() == "Install"
        button.click()
        assert calls
    finally:
        plugin.unload()


def test_a_closed_bar_stays_closed_after_a_reload(plugin_package, qgis_iface, fresh_bar, monkeypatch, tmp_path):
    monkeypatch.setenv("SOILVOLUME_ENGINE_ENV", str(tmp_path / "nothing-here"))
    plugin = load_plugin(plugin_package, qgis_iface)
    (item,) = our_items(fresh_bar)
    fresh_bar.popWidget(item)  # the user closes it
    plugin.unload()
    plugin = load_plugin(plugin_package, qgis_iface)
    try:
        assert our_items(fresh_bar) == []  # once per session
    finally:
        plugin.unload()


def test_a_failed_install_says_so_with_the_engines_last_lines(provider, qgis_iface, fresh_bar, monkeypatch, tmp_path):
    """A real environment whose packages did not install (the pip step skipped): the self-test
    fails, no stamp is written, the bar says it failed with the engine's own last line."""
    from soilvolume_qgis.plugin import environment
    from soilvolume_qgis.plugin.installer import DependencyBar

    folder = tmp_path / "engine"
    monkeypatch.setenv("SOILVOLUME_ENGINE_ENV", str(folder))
    monkeypatch.setattr(environment.Installer, "_install", lambda self, pip, site: None)
    outcome = []
    DependencyBar(qgis_iface).install(lambda ok, error: outcome.append((ok, error)))
    deadline = time.time() + 180
    while not outcome and time.time() < deadline:
        QgsApplication.processEvents()
        time.sleep(0.05)
    ((ok, error),) = outcome
    assert not ok and "No module named 'numpy'" in error, outcome
    assert environment.load(folder) is None and not (folder / environment.STAMP).exists()
    (critical,) = fresh_bar.get_messages(Qgis.MessageLevel.Critical)
    assert "Installing failed" in critical and "numpy" in critical
    assert fresh_bar.get_messages(Qgis.MessageLevel.Success) == []


def test_no_bar_when_the_environment_is_ready(plugin_package, qgis_iface, fresh_bar):
    plugin = load_plugin(plugin_package, qgis_iface)
    try:
        assert our_items(fresh_bar) == []
    finally:
        plugin.unload()


def test_install_button_runs_the_installer_algorithm_as_a_task(provider, qgis_iface, fresh_bar):
    """On a ready environment the task finishes at once (the stamp matches, the engine answers)
    and the bar says ready; the same task is what the button starts."""
    from soilvolume_qgis.plugin.installer import DependencyBar

    outcome = []
    task = DependencyBar(qgis_iface).install(lambda ok, error: outcome.append((ok, error)))
    deadline = time.time() + 120
    while not outcome and time.time() < deadline:
        QgsApplication.processEvents()
        time.sleep(0.05)
    assert outcome == [(True, "")], outcome
    assert task.status() == task.Complete
    # pytest-qgis's message bar records pushMessage as "title:text" per level
    assert any(m.startswith("Soil volume change:Installing") for m in fresh_bar.get_messages(Qgis.MessageLevel.Info))
    success = fresh_bar.get_messages(Qgis.MessageLevel.Success)
    assert success == ["Soil volume change:Installed and tested: the algorithms are ready."], success
    assert fresh_bar.get_messages(Qgis.MessageLevel.Critical) == []


def test_the_bars_install_button_reports_success(plugin_package, qgis_iface, fresh_bar, monkeypatch, tmp_path):
    """The Install button of the bar itself (its ``clicked`` passes ``checked``, never a callback):
    the environment becomes ready meanwhile, the install ends with the success message and no
    error (was: TypeError 'bool' object is not callable, no message)."""
    import os

    ready = os.environ["SOILVOLUME_ENGINE_ENV"]
    monkeypatch.setenv("SOILVOLUME_ENGINE_ENV", str(tmp_path / "nothing-here"))
    plugin = load_plugin(plugin_package, qgis_iface)
    errors = []
    monkeypatch.setattr("sys.excepthook", lambda kind, value, tb: errors.append(f"{kind.__name__}: {value}"))
    try:
        (item,) = our_items(fresh_bar)
        monkeypatch.setenv("SOILVOLUME_ENGINE_ENV", ready)  # installed meanwhile: the task ends at once
        item.findChild(QPushButton, "soilvolumeInstallDependencies").click()
        deadline = time.time() + 120
        while not fresh_bar.get_messages(Qgis.MessageLevel.Success) and not errors and time.time() < deadline:
            QgsApplication.processEvents()
            time.sleep(0.05)
        for _ in range(20):
            QgsApplication.processEvents()
            time.sleep(0.02)
    finally:
        plugin.unload()
    assert errors == []
    success = fresh_bar.get_messages(Qgis.MessageLevel.Success)
    assert success == ["Soil volume change:Installed and tested: the algorithms are ready."], success
