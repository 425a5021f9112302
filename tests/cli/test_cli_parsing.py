"""Command-line parsing: options are never abbreviated, on every sub-command."""
from __future__ import annotations

import argparse

import pytest

from ipcosim.harness.cli import build_parser, main, parsers


def _leaf_parsers() -> list[tuple[str, argparse.ArgumentParser]]:
    """Every sub-command's parser, named by its command path (``ipcosim rig status``)."""
    return [(p.prog, p) for p in parsers(build_parser())
            if not any(isinstance(a, argparse._SubParsersAction) for a in p._actions)]  # noqa: SLF001


def _required(p: argparse.ArgumentParser) -> list[str]:
    """Placeholder arguments for the required positionals and options (a valid choice where there are choices)."""
    out = []
    for action in p._actions:  # noqa: SLF001
        value = str(next(iter(action.choices))) if action.choices else "x"
        if not action.option_strings and action.nargs in (None, 1, "+"):
            out.append(value)
        elif action.required:
            out.extend([action.option_strings[0], value])
    return out


def _abbreviations(p: argparse.ArgumentParser) -> list[tuple[str, str]]:
    """(option, a prefix of it that names no option of ``p``) for every long option."""
    names = {s for a in p._actions for s in a.option_strings}  # noqa: SLF001
    out = []
    for option in sorted(n for n in names if n.startswith("--") and n != "--help"):
        prefix = option[:-1]
        while prefix in names:
            prefix = prefix[:-1]
        if len(prefix) > 2 and prefix not in names:
            out.append((option, prefix))
    return out


def test_every_subcommand_is_covered() -> None:
    progs = {prog for prog, _ in _leaf_parsers()}
    assert {"ipcosim run", "ipcosim rig status", "ipcosim rig reset", "ipcosim rig serve", "ipcosim describe"} <= progs


@pytest.mark.parametrize("prog,parser", _leaf_parsers(), ids=[prog for prog, _ in _leaf_parsers()])
def test_abbreviations_are_refused(prog: str, parser: argparse.ArgumentParser) -> None:
    """A prefix of an option is never taken for it: it stays unrecognized."""
    cases = _abbreviations(parser)
    assert cases or prog == "ipcosim list", f"{prog}: no long options found"
    for option, prefix in cases:
        _, extra = parser.parse_known_args([*_required(parser), prefix, "1"])
        assert prefix in extra, f"{prog}: {prefix} was taken for {option}"


def test_rig_status_token_is_not_token_file(capsys: pytest.CaptureFixture[str]) -> None:
    """`rig status --token SECRET` takes the token (it used to be read as `--token-file SECRET`)."""
    ns = build_parser().parse_args(["rig", "status", "--token", "SECRET"])
    assert ns.token == "SECRET" and ns.token_file is None
    ns = build_parser().parse_args(["rig", "reset", "--token", "SECRET"])
    assert ns.token == "SECRET"


def test_abbreviated_option_ends_in_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["run", "single-mass-lqr", "--stop", "1"])
    assert exc.value.code == 2
    # never taken for --stop-time; only suggested
    assert "ipcosim run: error: unknown option --stop; did you mean '--stop-time'?" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["--deb", "list"])
    assert exc.value.code == 2


@pytest.mark.parametrize("prog", sorted({p.prog for p in parsers(build_parser())}))
def test_help_of_every_command_prints(prog: str, capsys: pytest.CaptureFixture[str]) -> None:
    """``--help`` of ``ipcosim`` and of every sub-command prints its usage and exits 0 (a help string is a
    %-format: a bare ``95 % intervals`` once broke ``ipcosim --help``)."""
    with pytest.raises(SystemExit) as info:
        main([*prog.split()[1:], "--help"])
    assert info.value.code == 0
    assert capsys.readouterr().out.startswith(f"usage: {prog}")


def _project_version() -> str:
    """The version pyproject.toml gives the distribution."""
    import tomllib
    from pathlib import Path

    return tomllib.loads((Path(__file__).resolve().parents[2] / "pyproject.toml").read_text())["project"]["version"]


def test_version_is_the_installed_distributions(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(["--version"])
    assert info.value.code == 0
    assert capsys.readouterr().out == f"ipcosim {_project_version()}\n"


def test_metrics_name_the_version_that_ran(tmp_path) -> None:  # noqa: ANN001
    import json

    import ipcosim

    ipcosim.run("single-mass-lqr", stop_time=0.01, out=tmp_path)
    assert json.loads((tmp_path / "metrics.json").read_text())["ipcosim_version"] == _project_version()


@pytest.mark.parametrize("argv, line", [
    (["run", "single-mass-lqr", "--stop-tim", "1"], "ipcosim run: error: unknown option --stop-tim; did you mean "
                                                    "'--stop-time'"),
    (["sweep", "x", "--vary", "a=1", "--sample", "3"], "ipcosim sweep: error: unknown option --sample; did you "
                                                       "mean '--samples'"),
    (["rig", "serve", "--prot", "3"], "ipcosim rig serve: error: unknown option --prot; did you mean '--port'"),
    (["run", "single-mass-lqr", "surplus"], "ipcosim run: error: unexpected argument 'surplus'"),
])
def test_a_misspelt_option_names_the_closest_of_its_command(argv, line, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith(line), err
