"""The installer as a Windows or macOS user's install runs it, simulated here: the system set in
``plugin/platforms.py``, QGIS's Python layouts as folders, small shell scripts as the Pythons and
tools that misbehave (a venv whose base Python was removed, a blocked venv, Apple's tool shims)."""

from __future__ import annotations

import json
import os
import shutil
import stat
import subprocess
import sys
from dataclasses import asdict
from pathlib import Path

import pytest

REAL = os.path.realpath(sys.executable)


@pytest.fixture
def plugin(plugin_package, monkeypatch):
    """The plugin's modules, the system reset to the real one after the test."""
    from soilvolume_qgis.plugin import child, environment, interpreters, platforms

    for name in ("SYSTEM", "MACHINE", "MAC_VERSION"):
        monkeypatch.setattr(platforms, name, None)
    monkeypatch.delenv("SOILVOLUME_PYTHON", raising=False)
    return environment, interpreters, platforms, child


def script(path: Path, body: str) -> Path:
    """An executable shell script at ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("#!/bin/sh\n" + body + "\n")
    path.chmod(path.stat().st_mode | stat.S_IXUSR | stat.S_IXGRP | stat.S_IXOTH)
    return path


def caps_of(environment, venv: bool = True):
    return environment.Capabilities(sys.version_info[:2], venv=venv, ensurepip=False, pip=True)


# item 1: the oldest macOS, said before anything is downloaded; pip's refusal as a sentence


def test_an_old_mac_is_refused_in_one_line_before_anything_is_made(plugin, tmp_path):
    environment, _interpreters, platforms, _child = plugin
    platforms.SYSTEM, platforms.MACHINE, platforms.MAC_VERSION = "macos", "arm64", "13.6.1"
    folder = tmp_path / "engine"
    with pytest.raises(environment.InstallError) as caught:
        environment.Installer(folder, log=lambda _l: None).prepare()
    message = str(caught.value)
    assert "\n" not in message and "macOS 13.6.1" in message, message
    assert (
        "macOS 14 (Sonoma) or later on Apple silicon" in message and "macOS 13 (Ventura) or later on Intel" in message
    )
    assert not folder.exists()
    platforms.MACHINE, platforms.MAC_VERSION = "x86_64", "13.0"  # an Intel Mac on 13 is supported
    assert platforms.mac_too_old() == ""
    platforms.SYSTEM = "windows"
    assert platforms.mac_too_old() == ""


def test_pips_no_matching_distribution_becomes_a_sentence_about_the_system(plugin):
    _environment, _interpreters, platforms, _child = plugin
    platforms.SYSTEM, platforms.MACHINE = "windows", "ARM64"
    pip = "pip failed (exit 1); its last lines:\nERROR: No matching distribution found for pyproj==3.7.2"
    said = platforms.no_wheel(pip)
    assert said.startswith("pip found no wheel of pyproj==3.7.2 for this system (windows ARM64)"), said
    assert "Windows 10/11 x86-64" in said and "macOS 14 (Sonoma)" in said
    assert platforms.no_wheel("pip failed (exit 1): network unreachable") == ""


def test_the_installers_pip_refusal_is_that_sentence(plugin, tmp_path):
    environment, _interpreters, platforms, _child = plugin
    platforms.SYSTEM, platforms.MACHINE = "linux", "aarch64"
    pip = script(tmp_path / "pip", "echo 'ERROR: No matching distribution found for open3d-cpu==0.20.0' >&2\nexit 1")
    with pytest.raises(environment.InstallError) as caught:
        environment.Installer(tmp_path, log=lambda _l: None)._install([str(pip)], "")
    assert str(caught.value).startswith("pip found no wheel of open3d-cpu==0.20.0 for this system (linux aarch64)")


# item 2: a venv whose base Python was removed by a QGIS update


def old_qgis_python(tmp_path: Path) -> Path:
    """A Python that can be removed: this one's binary copied into an "old QGIS" folder (its
    standard library is found by its built-in prefix)."""
    base = tmp_path / "QGIS 3.40.1" / "bin" / Path(REAL).name
    base.parent.mkdir(parents=True)
    shutil.copy2(REAL, base)
    if subprocess.run([base, "-I", "-c", "import venv"], capture_output=True).returncode != 0:
        pytest.skip("this Python does not run from a copy of its binary")
    return base


def stamp(environment, folder: Path, base: str) -> None:
    interpreter = environment.venv_python(folder)
    env = environment.Environment(str(folder), "venv", interpreter, "", environment.lock_key(), {}, base=base)
    (folder / environment.STAMP).write_text(json.dumps(asdict(env)))


def test_a_venv_whose_base_python_was_removed_is_rebuilt(plugin, tmp_path):
    """macOS: the venv's bin/python is a link into the old app bundle, dangling after the update;
    the installer remade the venv from the new Python (was: kept the dangling link, every run
    failed with "No Python at")."""
    environment, interpreters, _platforms, _child = plugin
    old, folder, lines = old_qgis_python(tmp_path), tmp_path / "engine", []
    installer = environment.Installer(folder, log=lines.append, python=str(old), caps=caps_of(environment))
    assert installer._create(installer.caps)[0] == "venv"
    stamp(environment, folder, str(old))
    assert environment.load(folder) is not None
    shutil.rmtree(old.parents[1])  # the QGIS update removes the old QGIS
    assert environment.load(folder) is None
    assert "is gone" in environment.status(folder) and str(old) in environment.status(folder)
    assert not interpreters.starts(environment.venv_python(folder))
    installer = environment.Installer(folder, log=lines.append, python=REAL, caps=caps_of(environment))
    assert installer._create(installer.caps) == ("venv", environment.venv_python(folder), "")
    assert interpreters.starts(environment.venv_python(folder))
    assert f"home = {Path(REAL).parent}" in (folder / "pyvenv.cfg").read_text()
    assert any("no longer starts" in line and "rebuilding" in line for line in lines), lines
    assert installer.base == os.path.realpath(REAL)  # what the stamp records


def test_a_venv_built_from_another_python_is_rebuilt_from_the_one_chosen(plugin, tmp_path):
    """The user chose another Python (the install algorithm's parameter): the venv is remade from
    it, so the stamp's base is the Python the venv really runs on."""
    environment, _interpreters, _platforms, _child = plugin
    other, folder, lines = old_qgis_python(tmp_path), tmp_path / "engine", []
    first = environment.Installer(folder, log=lines.append, python=REAL, caps=caps_of(environment))
    first._create(first.caps)
    again = environment.Installer(folder, log=lines.append, python=REAL, caps=caps_of(environment))
    again._create(again.caps)
    assert not any("rebuilding" in line for line in lines)  # the same Python: kept as it is
    chosen = environment.Installer(folder, log=lines.append, python=str(other), caps=caps_of(environment))
    chosen._create(chosen.caps)
    assert chosen.base == str(other) and f"home = {other.parent}" in (folder / "pyvenv.cfg").read_text()
    assert any("was built from" in line and "rebuilding" in line for line in lines), lines


def test_a_venv_launcher_without_its_python_is_rebuilt(plugin, tmp_path):
    """Windows: the venv's python.exe is still there but says "No Python at" (its base is gone):
    the stamp is not ready and the installer clears and remakes the venv."""
    environment, interpreters, _platforms, _child = plugin
    folder, lines = tmp_path / "engine", []
    installer = environment.Installer(folder, log=lines.append, python=REAL, caps=caps_of(environment))
    installer._create(installer.caps)
    gone = tmp_path / "QGIS 3.40.1" / "apps" / "Python312" / "python.exe"
    launcher = Path(environment.venv_python(folder))
    launcher.unlink()
    script(launcher, f"echo \"No Python at '{gone}'\" >&2\nexit 103")
    (folder / "leftover.txt").write_text("of the old venv")
    stamp(environment, folder, str(gone))
    assert environment.load(folder) is None and "is gone" in environment.status(folder)
    assert installer._create(installer.caps)[0] == "venv"
    assert interpreters.starts(str(launcher)) and not (folder / "leftover.txt").exists()


# item 3: QGIS's own Python found in its Windows and macOS layouts; never python3 from the PATH


def test_qgis_python_is_found_in_the_windows_and_macos_layouts(plugin, tmp_path):
    _environment, interpreters, platforms, _child = plugin
    platforms.SYSTEM = "windows"
    root = tmp_path / "QGIS 3.40.1"
    exe = script(root / "bin" / "qgis-bin.exe", "exit 0")
    python = script(root / "apps" / "Python312" / "python.exe", "exit 0")
    assert interpreters.qgis_python(str(exe), [str(python.parent)], (3, 12)) == str(python)
    platforms.SYSTEM = "macos"
    app = tmp_path / "QGIS-LTR.app" / "Contents"
    exe = script(app / "MacOS" / "QGIS", "exit 0")
    framework = app / "Frameworks" / "Python.framework" / "Versions" / "3.12"
    framework.mkdir(parents=True)
    assert interpreters.qgis_python(str(exe), [str(framework)], (3, 12)) == ""  # none there yet
    beside = script(app / "MacOS" / "bin" / "python3", "exit 0")
    assert interpreters.qgis_python(str(exe), [str(framework)], (3, 12)) == str(beside)
    python = script(framework / "bin" / "python3.12", "exit 0")
    assert interpreters.qgis_python(str(exe), [str(framework)], (3, 12)) == str(python)


def test_without_qgis_python_the_paths_python3_is_never_run(plugin, tmp_path, monkeypatch):
    """A macOS QGIS with no Python found beside it: one line naming QGIS's Options route and the
    install algorithm's parameter (was: /usr/bin/python3 from the PATH was run: Apple's 3.9 or
    its "install developer tools" dialog)."""
    environment, _interpreters, platforms, _child = plugin
    platforms.SYSTEM, platforms.MACHINE, platforms.MAC_VERSION = "macos", "arm64", "14.5"
    app = tmp_path / "QGIS.app" / "Contents"
    monkeypatch.setattr(sys, "executable", str(script(app / "MacOS" / "QGIS", "exit 0")))
    for name in ("prefix", "exec_prefix", "base_prefix", "base_exec_prefix"):
        monkeypatch.setattr(sys, name, str(app / "Resources" / "python"))
    ran = tmp_path / "python3-was-run"
    script(tmp_path / "path" / "python3", f"touch '{ran}'\necho '[[3, 9], true, true, true]'")
    monkeypatch.setenv("PATH", f"{tmp_path / 'path'}{os.pathsep}{os.environ['PATH']}")
    with pytest.raises(environment.InstallError) as caught:
        environment.Installer(tmp_path / "engine", log=lambda _l: None).prepare()
    message = str(caught.value)
    assert not ran.exists()
    assert "\n" not in message and "QGIS's own Python was not found" in message
    assert "Settings > Options > System > Environment" in message and "Install dependencies" in message


def test_a_wrong_python_is_refused_in_one_line(plugin, tmp_path):
    _environment, interpreters, _platforms, _child = plugin
    old = script(tmp_path / "python3.9", "echo '[[3, 9], true, true, true]'")
    broken = script(tmp_path / "python-broken", "echo 'dyld: Library not loaded: libpython3.12.dylib' >&2\nexit 134")
    for python, said in (
        (old, "is Python 3.9"),
        (broken, "dyld: Library not loaded"),
        (tmp_path / "nowhere", "no such"),
    ):
        with pytest.raises(interpreters.InstallError) as caught:
            interpreters.check(str(python), "the Python parameter")
        message = str(caught.value)
        assert "\n" not in message and message.startswith(f"{python} (the Python parameter)"), message
        assert said in message and "3.11 or 3.12" in message and "Install dependencies" in message


@pytest.mark.skipif(not Path("/usr/bin/python3").is_file(), reason="needs a /usr/bin/python3 to stand for Apple's")
def test_on_macos_without_developer_tools_usr_bin_python3_is_refused_unrun(plugin, tmp_path, monkeypatch):
    """Apple's /usr/bin/python3 without the command-line tools is a shim that opens an install
    dialog: refused from xcode-select's answer, never started."""
    _environment, interpreters, platforms, _child = plugin
    platforms.SYSTEM = "macos"
    script(tmp_path / "bin" / "xcode-select", "exit 2")
    monkeypatch.setenv("PATH", f"{tmp_path / 'bin'}{os.pathsep}{os.environ['PATH']}")
    started = []
    monkeypatch.setattr(interpreters, "probe", lambda python: started.append(python))
    apple = r"^/usr/bin/python3 \(QGIS's own Python\) is Apple's placeholder"
    with pytest.raises(interpreters.InstallError, match=apple):
        interpreters.check("/usr/bin/python3", "QGIS's own Python")
    assert started == []


def test_the_install_algorithm_takes_a_python_and_keeps_it(plugin, provider, tmp_path, monkeypatch):
    """The algorithm's optional PYTHON: a wrong one refused (and not kept), a right one kept in
    QGIS's settings for the message bar's Install button."""
    from qgis.core import QgsProcessingException, QgsSettings
    from soilvolume_qgis.processing import installdependencies as alg

    monkeypatch.setattr(alg, "PYTHON_SETTING", "soilvolume-tests/python")
    settings = QgsSettings()
    settings.remove("soilvolume-tests/python")
    old = script(tmp_path / "python3.9", "echo '[[3, 9], true, true, true]'")
    with pytest.raises(QgsProcessingException, match=r"is Python 3\.9"):
        alg.chosen_python(str(old))
    assert alg.chosen_python("") == ""
    assert alg.chosen_python(REAL) == REAL
    assert alg.chosen_python("") == REAL
    settings.remove("soilvolume-tests/python")
    assert "PYTHON" in [p.name() for p in provider.algorithm("installdependencies").parameterDefinitions()]


# item 4: a venv that cannot be made or whose Python is blocked: the --target folder instead


@pytest.mark.parametrize("how", ["venv fails", "venv's python blocked"])
def test_a_venv_that_does_not_work_falls_back_to_a_target_folder(plugin, tmp_path, how):
    environment, _interpreters, _platforms, _child = plugin
    if how == "venv fails":
        venv = 'echo "Error: [WinError 5] Access is denied" >&2; exit 1'
    else:  # made, but its Python is stopped by a software restriction policy
        venv = (
            'for last; do :; done; mkdir -p "$last/bin"; echo "home = /x" > "$last/pyvenv.cfg"\n'
            "printf '#!/bin/sh\\necho blocked by group policy >&2\\nexit 1\\n' > \"$last/bin/python\"\n"
            'chmod +x "$last/bin/python"; exit 0'
        )
    base = script(tmp_path / "qgis" / "python3", f'case "$*" in *"-m venv"*) {venv};; esac\nexec "{REAL}" "$@"')
    folder, lines = tmp_path / "engine", []
    installer = environment.Installer(folder, log=lines.append, python=str(base), caps=caps_of(environment))
    mode, interpreter, site, pip = installer.prepare()
    assert (mode, interpreter, site) == ("target", str(base), str(folder / "site-packages"))
    assert pip[0] == str(base) and pip[-2:] == ["-m", "pip"]
    assert any("falling back to a --target folder" in line for line in lines), lines
    env = environment.Environment(str(folder), mode, interpreter, site, "", {})
    run = subprocess.run(env.python(["-c", "import sys;print(sys.flags.isolated, sys.flags.no_site)"]), **TEXT)
    assert run.stdout.split() == ["1", "1"], run


TEXT = {"capture_output": True, "text": True, "timeout": 120}


# item 8: the install's self-test runs what only runs off Linux


def test_the_install_selftest_imports_csf_and_runs_a_spawned_worker_in_the_environment(plugin, tmp_path):
    """In the engine's own isolated environment (-I, the engine found through the command line's
    path only), as the installer runs it: a spawned worker must find the engine and its packages."""
    environment, _interpreters, _platforms, _child = plugin
    ready = environment.load(Path(os.environ["SOILVOLUME_ENGINE_ENV"]))
    command = ready.command(["selftest", "--out", str(tmp_path / "run"), "--progress", "jsonl"])
    run = subprocess.run(command, env=environment.child_environ(), **TEXT)
    assert run.returncode == 0, run.stderr[-2000:]
    result = json.loads(run.stdout.strip().splitlines()[-1])
    assert "CSF" in result["versions"] and 0 < result["dask_worker_s"] < 120, result
    assert "starting a Dask worker process (spawned)" in run.stdout


# item 9: the environment in the local profile on Windows


def test_on_windows_the_environment_is_in_the_local_profile(plugin, tmp_path, monkeypatch):
    environment, _interpreters, platforms, _child = plugin
    monkeypatch.delenv("SOILVOLUME_ENGINE_ENV")
    roaming, local = tmp_path / "AppData" / "Roaming", tmp_path / "AppData" / "Local"
    monkeypatch.setenv("APPDATA", str(roaming))
    monkeypatch.setenv("LOCALAPPDATA", str(local))
    profile = roaming / "QGIS" / "QGIS3" / "profiles" / "default"
    platforms.SYSTEM = "windows"
    expected = local / "QGIS" / "QGIS3" / "profiles" / "default" / "soilvolume" / "engine"
    assert environment.env_folder(profile) == expected
    old = profile / "soilvolume" / "engine"  # where earlier versions put it: said after an install
    old.mkdir(parents=True)
    (old / environment.STAMP).write_text("{}")
    lines = []
    environment.Installer(expected, log=lines.append).roaming_note()
    assert lines == [
        f"An earlier version's environment is in the roaming profile ({old}, 0 MB): "
        "delete it once no QGIS with that version uses it"
    ]
    elsewhere = tmp_path / "portable" / "profiles" / "default"  # --profiles-path: kept where chosen
    assert environment.env_folder(elsewhere) == elsewhere / "soilvolume" / "engine"
    platforms.SYSTEM = "linux"
    assert environment.env_folder(profile) == profile / "soilvolume" / "engine"


# item 10: macOS without the command-line tools: no compiler run, no dialog


@pytest.mark.parametrize("tools", [False, True])
def test_macos_kernels_are_built_only_with_the_command_line_tools(plugin, tmp_path, monkeypatch, tools):
    environment, _interpreters, platforms, _child = plugin
    platforms.SYSTEM = "macos"
    script(tmp_path / "bin" / "xcode-select", "echo /Library/Developer/CommandLineTools\nexit 0" if tools else "exit 2")
    monkeypatch.setenv("PATH", f"{tmp_path / 'bin'}{os.pathsep}{os.environ['PATH']}")
    built = tmp_path / "compiler-was-run"
    python = script(tmp_path / "env" / "bin" / "python", f"touch '{built}'\necho 'built: x'")
    lines = []
    env = environment.Environment(str(tmp_path / "env"), "venv", str(python), "", "", {})
    environment.Installer(tmp_path / "env", log=lines.append)._kernels(env)
    assert built.exists() == tools
    if not tools:
        assert lines and "xcode-select --install" in lines[0] and "not built" in lines[0], lines


# item 12: UTF-8 children, a temporary folder Windows will not remove, crash codes in hex


def test_every_python_the_plugin_starts_runs_in_utf8_mode(plugin, tmp_path):
    environment, _interpreters, _platforms, _child = plugin
    ready = environment.load(Path(os.environ["SOILVOLUME_ENGINE_ENV"]))
    code = "import sys;print(sys.flags.utf8_mode, sys.stdout.encoding, 'Jürgen')"
    run = subprocess.run(ready.python(["-c", code]), env={"LC_ALL": "C", "PATH": os.environ["PATH"]}, **TEXT)
    assert run.stdout.split() == ["1", "utf-8", "Jürgen"], run
    command = ready.command(["--help"])
    assert command[1:4] == ["-I", "-X", "utf8"]


def test_a_selftest_folder_windows_will_not_remove_does_not_fail_the_install(plugin, tmp_path, monkeypatch):
    """A file of the self-test still held open (an antivirus scan, a worker closing): Windows
    refuses to delete it (PermissionError) and the passed self-test must not fail for it (was:
    the temporary folder's cleanup raised out of the install)."""
    environment, _interpreters, _platforms, _child = plugin
    result = {"type": "result", "net_m3": 10.0, "true_net_m3": 10.1, "versions": {"numpy": "1.26.4"}}
    code = (
        "import sys,pathlib;out=pathlib.Path(sys.argv[sys.argv.index('--out')+1]);"
        f"(out.parent/'held.dat').write_text('x');print({json.dumps(json.dumps(result))})"
    )
    monkeypatch.setattr(environment.Environment, "command", lambda self, args: [sys.executable, "-c", code, *args])
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path))  # what is left stays in the test's folder
    unlink = os.unlink

    def held(path, *args, **kwargs):
        if str(path).endswith("held.dat"):
            raise PermissionError(13, "The process cannot access the file: it is being used", str(path))
        return unlink(path, *args, **kwargs)

    monkeypatch.setattr(os, "unlink", held)
    env = environment.Environment(str(tmp_path), "venv", sys.executable, "", "", {})
    versions = environment.Installer(tmp_path, log=lambda _l: None)._selftest(env)
    monkeypatch.setattr(os, "unlink", unlink)
    assert versions == {"numpy": "1.26.4"}
    assert list(tmp_path.glob("soilvolume-selftest-*/held.dat"))  # left behind, as on Windows


def test_windows_crash_codes_are_shown_in_hex(plugin):
    _environment, _interpreters, platforms, child = plugin
    platforms.SYSTEM = "windows"
    text = child.crash_text(3221225477, ["Windows fatal exception: access violation"])
    assert "exit status 0xC0000005, access violation" in text, text
    assert "exit status 0xC0000409" in child.crash_text(-1073740791, [])
    assert "exit status 2)" in child.crash_text(2, [])
    platforms.SYSTEM = "linux"
    assert "signal SIGSEGV" in child.crash_text(-11, [])
