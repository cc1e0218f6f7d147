"""Install (or update) the engine's Python environment: the same installer as the message bar's
Install button and the Plugins menu, headless for ``qgis_process`` on servers."""

from __future__ import annotations

from typing import Any

from qgis.core import (
    QgsProcessingAlgorithm,
    QgsProcessingContext,
    QgsProcessingException,
    QgsProcessingFeedback,
    QgsProcessingOutputFolder,
    QgsProcessingOutputNumber,
    QgsProcessingOutputString,
    QgsProcessingParameterBoolean,
    QgsProcessingParameterFile,
    QgsSettings,
)

from ..plugin import environment, interpreters
from .base import SoilVolumeAlgorithm

HELP = """\
<p>Creates the Python environment the engine runs in, a folder of the plugin's own in the QGIS
profile (<i>soilvolume/engine</i>): a Python virtual environment with exactly the engine's pinned
packages (numpy, scipy, pyproj, rasterio, Open3D, laspy with LAZ support, Dask, Fiona), isolated
from QGIS's own Python packages and libraries. Then it tests the engine in it (every package
imports; a tiny seeded pair is estimated) and says the plugin is ready only when that passed.</p>
<h3>Inputs</h3>
<p><b>Reinstall</b> rebuilds the packages even when the environment is up to date. Running it again
is quick when everything is there; after a plugin update it updates the environment, and after a
QGIS update that removed the Python it was built from it rebuilds it.</p>
<p><b>Python to build the environment from</b> (optional): a Python 3.11 or 3.12 interpreter
(e.g. from python.org: on Windows <i>python.exe</i>, on macOS
<i>/Library/Frameworks/Python.framework/Versions/3.12/bin/python3</i>), for a QGIS whose own Python
is older or cannot be found. Kept in QGIS's settings for the next installs (the message bar's
button uses it too); empty: the one kept, else QGIS's own.</p>
<h3>Outputs</h3>
<p>The environment's folder, the Python that runs the engine, the versions installed (JSON) and
the seconds it took. Needs about 800 MB and access to PyPI (pip's own settings, e.g. a proxy or
an index mirror, apply). On Windows the folder is in the local profile
(<i>%LOCALAPPDATA%</i>), not the roaming one. The environment variables SOILVOLUME_PYTHON (another
Python to build it from) and SOILVOLUME_ENGINE_ENV (another folder) are set in Settings > Options >
System > Environment (on macOS: QGIS > Preferences…): QGIS started from Finder or the Start menu
sees no shell variables.</p>"""
#: where the Python chosen with the PYTHON parameter is kept
PYTHON_SETTING = "soilvolume/python"


class InstallDependencies(SoilVolumeAlgorithm):
    """The engine's environment: create, install the lock, self-test."""

    _name = "installdependencies"
    _display_name = "Install dependencies (the engine's Python environment)"
    _help = HELP
    _tags = "install,dependencies,pip,environment,setup"
    _group = "Set-up"
    _group_id = "setup"

    def flags(self):
        return super().flags() | QgsProcessingAlgorithm.FlagNoThreading  # one installer at a time

    def initAlgorithm(self, config: dict[str, Any] | None = None) -> None:  # noqa: N802
        self.addParameter(QgsProcessingParameterBoolean("FORCE", self.tr("Reinstall"), defaultValue=False))
        python = QgsProcessingParameterFile(
            "PYTHON", self.tr("Python to build the environment from (3.11 or 3.12)"), optional=True
        )
        self.addParameter(python)
        self.addOutput(QgsProcessingOutputFolder("ENVIRONMENT", self.tr("Environment folder")))
        self.addOutput(QgsProcessingOutputString("PYTHON", self.tr("Python that runs the engine")))
        self.addOutput(QgsProcessingOutputString("VERSIONS", self.tr("Versions installed (JSON)")))
        self.addOutput(QgsProcessingOutputNumber("SECONDS", self.tr("Seconds the install took")))

    def processAlgorithm(  # noqa: N802
        self, parameters: dict[str, Any], context: QgsProcessingContext, feedback: QgsProcessingFeedback
    ) -> dict[str, Any]:
        import json

        installer = environment.Installer(
            environment.env_folder(),
            log=feedback.pushInfo,
            progress=feedback.setProgress,
            cancelled=feedback.isCanceled,
            python=chosen_python(self.parameterAsFile(parameters, "PYTHON", context)),
        )
        try:
            env = installer.run(force=self.parameterAsBool(parameters, "FORCE", context))
        except environment.InstallError as exc:
            raise QgsProcessingException(f"Installing the engine's environment failed: {exc}") from exc
        return {
            "ENVIRONMENT": env.folder,
            "PYTHON": env.interpreter,
            "VERSIONS": json.dumps(env.versions),
            "SECONDS": env.seconds,
        }


def chosen_python(given: str) -> str:
    """The Python to build from: ``given`` (checked, then kept in QGIS's settings), else the one
    kept ("": QGIS's own or $SOILVOLUME_PYTHON). A wrong one is refused in one line, not kept."""
    settings = QgsSettings()
    if not given:
        return str(settings.value(PYTHON_SETTING, "", str) or "")
    try:
        interpreters.check(given, "the Python parameter")
    except interpreters.InstallError as exc:
        raise QgsProcessingException(str(exc)) from None
    settings.setValue(PYTHON_SETTING, given)
    return given
