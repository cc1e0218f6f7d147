"""The installer's fallbacks, run for real on this machine's Python with what it offers
overridden: a stock QGIS may lack ``ensurepip`` (Debian's python3-venv), pip (python3-pip) and
even ``venv``.

- No venv, no ensurepip, no pip (the hardest case): pip's wheel from PyPI (SHA-256 checked) runs
  from the wheel itself and installs the whole lock into a ``--target`` folder; the engine passes
  its self-test there, the stamp is written, the engine runs isolated from the system's packages
  (Debian's pyproj 3.4.1 is not seen) and a re-run is a no-op.
- A venv without ensurepip: the same wheel bootstraps the venv's own pip, which installs into
  the venv and nowhere else. From there on the venv path is the stock one, which the clean-profile
  install of ``test_qgis_isolation.py`` runs in full (lock, self-test, real pairs); installing the
  whole lock a second time here would prove nothing more and cost ~40 s.
"""

from __future__ import annotations

import json
import subprocess

import pytest

pytestmark = pytest.mark.slow
SYSTEM_PYTHON = "/usr/bin/python3"
PROBE = "import {module},sys,json;print(json.dumps([{module}.__version__, {module}.__file__, sys.path]))"


def probe(env, module: str) -> tuple[str, str, list[str]]:
    run = subprocess.run(env.python(["-c", PROBE.format(module=module)]), capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    return tuple(json.loads(run.stdout))


def test_no_venv_no_pip_installs_a_working_isolated_engine(plugin_package, tmp_path):
    from soilvolume_qgis.plugin import environment

    folder, lines = tmp_path / "engine", []
    caps = environment.Capabilities((3, 11), venv=False, ensurepip=False, pip=False)
    env = environment.Installer(folder, log=lines.append, python=SYSTEM_PYTHON, caps=caps).run()
    assert env.mode == "target" and env.site == str(folder / "site-packages")
    assert environment.load(folder) == env
    assert any("downloading pip's wheel from PyPI" in line for line in lines), lines[:20]
    assert any(line.startswith("Self-test passed") for line in lines)
    assert not any(line.startswith("Native kernels: not built") for line in lines)  # a C compiler is here
    assert list((environment.PLUGIN_DIR / "soilvolume" / "native").glob("_soilvolume_kernels-*"))
    version, where, path = probe(env, "pyproj")
    assert version == "3.7.2" and where.startswith(env.site)  # the lock's pyproj, from the folder
    assert [p for p in path if "dist-packages" in p or "site-packages" in p] == [env.site]
    again = []
    environment.Installer(folder, log=again.append).run()
    assert again == [f"The engine's environment is ready ({folder}); nothing to do."]


def test_a_venv_without_ensurepip_gets_its_own_pip_from_pypi(plugin_package, tmp_path):
    from soilvolume_qgis.plugin import environment

    folder, lines = tmp_path / "engine", []
    caps = environment.Capabilities((3, 11), venv=True, ensurepip=False, pip=False)
    installer = environment.Installer(folder, log=lines.append, python=SYSTEM_PYTHON, caps=caps)
    mode, interpreter, site, pip = installer.prepare()
    assert (mode, interpreter, site) == ("venv", environment.venv_python(folder), "")
    assert any("downloading pip's wheel from PyPI" in line for line in lines), lines
    assert pip == [interpreter, *environment.FLAGS, "-m", "pip"]  # the venv's own pip
    pin = next(line for line in environment.LOCK.read_text().splitlines() if line.startswith("toolz=="))
    done = subprocess.run(
        [*pip, "install", "--no-deps", "--only-binary=:all:", "--no-input", pin],
        capture_output=True,
        text=True,
        timeout=300,
        env=environment.child_environ(),
    )
    assert done.returncode == 0, done.stderr[-2000:]
    env = environment.Environment(str(folder), mode, interpreter, site, environment.lock_key(), {})
    for module in ("pip", "toolz"):
        _version, where, path = probe(env, module)
        assert where.startswith(str(folder)), (module, where)  # in the venv, not the system's
    assert not [p for p in path if "dist-packages" in p]  # no system site-packages
    assert environment.load(folder) is None  # not ready: no stamp before a self-test


def test_a_plugin_update_makes_the_environment_stale(plugin_package, tmp_path, monkeypatch):
    """The stamp records the lock and the plugin version: after an update the environment is
    not ready (the bar and the algorithms say why) and the installer installs again instead of
    answering "nothing to do"."""
    import os
    from dataclasses import asdict
    from pathlib import Path

    from soilvolume_qgis.plugin import environment

    ready = environment.load(Path(os.environ["SOILVOLUME_ENGINE_ENV"]))
    assert ready is not None
    folder = tmp_path / "engine"
    folder.mkdir()
    (folder / environment.STAMP).write_text(json.dumps({**asdict(ready), "folder": str(folder)}))
    assert environment.load(folder) is not None and environment.status(folder) == ""
    monkeypatch.setattr(environment, "plugin_version", lambda: "99.0.0")  # the plugin was updated
    assert environment.load(folder) is None
    assert "made for another version of the plugin" in environment.status(folder)
    calls = []

    def prepare(self):
        calls.append(self.folder)
        raise environment.InstallError("stopped before installing")

    monkeypatch.setattr(environment.Installer, "prepare", prepare)
    with pytest.raises(environment.InstallError, match="stopped before installing"):
        environment.Installer(folder, log=lambda _line: None).run()
    assert calls == [folder]
