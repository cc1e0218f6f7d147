"""The command line as a package (``soilvolume/cli/``): one module per command, each declaring its
sub-parser beside what it runs, and every command's ``--help`` built from the option table."""

from __future__ import annotations

import argparse
import importlib
import re
import subprocess
import sys

import pytest

from soilvolume.cli import build_parser, main
from soilvolume.core import wording
from soilvolume.options import COMMANDS as TABLE_COMMANDS
from soilvolume.options import Options, command_fields

SKIP = {"keep_registered_cloud"}  # estimate's --registered-cloud says it
ALL_FLAGS = {"--" + f.name.replace("_", "-") for c in TABLE_COMMANDS for f in command_fields(c)} - {
    "--keep-registered-cloud"
}


COMMANDS = ["estimate", "dem", "register", "volume", "series", "stockpile", "pipeline", "demo", "selftest"]


def _commands() -> list[str]:
    (sub,) = [a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)]  # noqa: SLF001
    return list(sub.choices)


def _help(capsys, command: str) -> str:
    with pytest.raises(SystemExit) as done:
        main([command, "--help"])
    assert done.value.code == 0
    return capsys.readouterr().out


def _listed(flag: str, text: str) -> bool:
    """``flag`` named in ``text`` as itself (``--cell`` is not ``--cell-size``)."""
    return re.search(re.escape(flag) + r"(?![-\w])", text) is not None


def test_the_program_has_its_nine_commands_in_order():
    assert _commands() == [
        "estimate",
        "dem",
        "register",
        "volume",
        "series",
        "stockpile",
        "pipeline",
        "demo",
        "selftest",
    ]


@pytest.mark.parametrize(
    "command", ["estimate", "dem", "register", "volume", "series", "stockpile", "pipeline", "demo", "selftest"]
)
def test_each_help_lists_the_options_the_table_declares_for_its_command_with_their_help(capsys, command):
    """Every option of ``command_fields(command)`` in ``--help`` with the table's help and default;
    a command of the table takes no other option of it."""
    text = _help(capsys, command)
    squeezed = re.sub(r"\s+", "", text)  # argparse wraps the help where it likes
    declared = [f for f in command_fields(command) if f.name not in SKIP] if command in TABLE_COMMANDS else []
    for f in declared:
        flag = "--" + f.name.replace("_", "-")
        assert _listed(flag, text), (command, flag)
        said = f"{wording.cli(f.metadata['help'])} (default: {f.default})"
        assert re.sub(r"\s+", "", said) in squeezed, (command, flag)
    (sub,) = [a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)]  # noqa: SLF001
    taken = {s for a in sub.choices[command]._actions for s in a.option_strings}  # noqa: SLF001
    if command in TABLE_COMMANDS:  # volume's --zones and demo's --seed are their own, not the table's
        assert taken & ALL_FLAGS == {"--" + f.name.replace("_", "-") for f in declared}, command


def test_the_table_reaches_every_option_through_some_command():
    fields = {f.name for c in TABLE_COMMANDS for f in command_fields(c)}
    assert fields == set(Options.__dataclass_fields__)


@pytest.mark.parametrize(
    "command", ["estimate", "dem", "register", "volume", "series", "stockpile", "pipeline", "demo", "selftest"]
)
def test_each_command_lives_in_its_own_module_with_its_parser_and_its_run(command):
    """``soilvolume.cli.<command>`` declares the sub-parser (``add_parser``) and runs it (``run``);
    the program's parser and dispatch are made of those modules alone."""
    module = importlib.import_module(f"soilvolume.cli.{command}")
    assert module.NAME == command
    assert callable(module.add_parser) and callable(module.run)
    app = importlib.import_module("soilvolume.cli.app")
    assert app.command(command) is module  # the registry resolves the name to its module
    sub = argparse.ArgumentParser().add_subparsers()
    module.add_parser(sub)
    assert list(sub.choices) == [command]  # the module declares its own sub-parser, and only it


@pytest.mark.parametrize("command", [*COMMANDS, None])
def test_a_command_line_loads_the_module_of_its_command_and_no_other(command):
    """The registry imports only the module of the command being run (start-up): ``estimate``
    never loads the scene generators of ``demo`` and ``selftest`` nor ``pipeline``'s emitter;
    without a command (``--help``) all nine are loaded, to be listed."""
    argv = [command, "--out", "x"] if command else ["--help"]
    code = (
        "import sys\n"
        "from soilvolume.cli import build_parser\n"
        f"build_parser({argv!r})\n"
        f"print(sorted(c for c in {COMMANDS!r} if 'soilvolume.cli.' + c in sys.modules))\n"
        "print('soilvolume.scenes.demo' in sys.modules, 'soilvolume.pipelines.emit' in sys.modules)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    loaded, heavy = done.stdout.splitlines()
    assert loaded == str(sorted([command] if command else COMMANDS))
    assert heavy == f"{command in ('demo', None)} {command in ('pipeline', None)}"
