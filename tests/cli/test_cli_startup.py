"""The command line starts at once: ``ipcosim --version``, ``--help`` and a command's ``--help`` load
only what they print, and a command loads what it runs and no other command's options. Checked by the
modules a fresh interpreter has loaded (never by a wall-clock time: these machines are shared), in
the ``ipcosim`` console command's own process."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from ipcosim.harness import cli

#: What a command's one line of help never needs: numpy (the run options' grammar), the SSP reader.
HEAVY = ("numpy", "lxml", "ipcosim.harness.scenario.ssp", "ipcosim.harness.api.options")

PROBE = """
import json, sys
from ipcosim.harness.cli import main
try:
    main({argv!r})
except SystemExit:
    pass
print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in ('numpy', 'lxml', 'ipcosim'))))
"""


def _loaded(argv: list[str]) -> set[str]:
    done = subprocess.run([sys.executable, "-c", PROBE.format(argv=argv)], capture_output=True, text=True,
                          timeout=120)
    return set(json.loads(done.stdout.strip().splitlines()[-1]))


@pytest.mark.parametrize("argv", [["--version"], ["--help"], ["list", "--help"], ["compare", "--help"],
                                  ["identify", "--help"], ["rig", "serve", "--help"],
                                  ["linearize", "--help"], ["nosuchcommand"]], ids=" ".join)
def test_help_and_version_load_nothing_heavy(argv: list[str]) -> None:
    loaded = _loaded(argv)
    assert not [m for m in HEAVY if m in loaded], sorted(loaded)


def test_a_command_builds_its_own_options_only() -> None:
    loaded = _loaded(["describe", "--help"])
    assert "ipcosim.harness.api.options" not in loaded  # run's options are not built for describe
    assert "ipcosim.harness.api.options" in _loaded(["run", "--help"])  # run's are, for run


def test_every_command_is_listed_by_help_whichever_is_built() -> None:
    outline = {p.prog for p in cli.parsers(cli.build_parser(""))}
    whole = {p.prog for p in cli.parsers(cli.build_parser())}
    commands = {f"ipcosim {name}" for name in cli.COMMANDS}
    assert commands <= outline and commands <= whole
    assert "ipcosim rig serve" in whole and "ipcosim rig serve" not in outline  # the outline has no options


def test_a_command_loads_no_other_commands_module() -> None:
    loaded = _loaded(["run", "--help"])
    assert "ipcosim.harness.cli.run" in loaded
    assert not [m for m in loaded if m.startswith("ipcosim.harness.cli.") and m != "ipcosim.harness.cli.run"]


@pytest.mark.parametrize("argv", [["-h", "run"], ["--debug", "--help", "list"]], ids=" ".join)
def test_the_help_asked_for_before_a_command_lists_every_command(argv: list[str], capsys) -> None:
    with pytest.raises(SystemExit):
        cli.main(["--help"])
    alone = capsys.readouterr().out
    with pytest.raises(SystemExit):
        cli.main(argv)
    assert capsys.readouterr().out == alone
    assert set(cli.COMMANDS) <= {line.split()[0] for line in alone.splitlines() if line.startswith("    ")}


@pytest.mark.parametrize("argv, named", [(["run", "x"], "run"), (["--debug", "list"], "list"),
                                         (["--version"], ""), (["lst"], ""), ([], "")])
def test_the_command_is_read_from_the_words_before_parsing(argv: list[str], named: str) -> None:
    assert cli.command_named(argv) == named
