"""The engine's environment from the desktop: a message bar with an Install button at plugin
load when it is missing (once), none when it is ready, and the button running the same
installer as ``soilvolume:installdependencies`` (a background task that reports success only
after the engine's self-test passed)."""

from __future__ import annotations

import time

import pytest
from qgis.core import QgsApplication
from qgis.PyQt.QtWidgets import QPushButton


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
    assert any("Installed and tested" in item.text() for item in our_items(fresh_bar))
