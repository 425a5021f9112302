"""Each option of a run is declared once, as a field of RunOptions: the ``ipcosim run`` parser, the
command line's conversion and :func:`ipcosim.run` are written from the fields, so an option added
or spelled anywhere else fails here; and a run's metrics.json is written once, with its final figures."""
from __future__ import annotations

import argparse
import dataclasses
import inspect
import json

import pytest
from master_mocks import loop_factory, loop_system

import ipcosim
from ipcosim.errors import UsageError
from ipcosim.harness import cli
from ipcosim.harness.api.engine import Prepared
from ipcosim.harness.api.options import RunOptions, run_options
from ipcosim.harness.master.results import Result

#: The parameters of ipcosim.run that are not options of a run: the master's extension points and **more.
EXTENSION_POINTS = {"observers", "manipulators", "more"}


def _run_parser() -> argparse.ArgumentParser:
    return next(p for p in cli.parsers(cli.build_parser()) if p.prog == "ipcosim run")


def _arguments() -> dict[str, argparse.Action]:
    """The ``ipcosim run`` parser's arguments by their first spelling, ``--help`` left out."""
    return {(a.option_strings[0] if a.option_strings else a.dest): a for a in _run_parser()._actions  # noqa: SLF001
            if not isinstance(a, argparse._HelpAction)}  # noqa: SLF001


def test_the_run_parser_holds_exactly_the_fields_flags() -> None:
    declared = {how.flag for _, how in run_options() if how.flag}
    parsed = set(_arguments())
    assert parsed - declared == set(), "an option of `ipcosim run` added outside RunOptions's fields"
    assert declared - parsed == set(), "a field's flag missing from `ipcosim run`"


@pytest.mark.parametrize("name", [name for name, how in run_options() if how.flag])
def test_each_argument_is_its_field_help_metavar_and_choices(name: str) -> None:
    how = RunOptions.__dataclass_fields__[name].metadata["option"]
    action = _arguments()[how.flag]
    assert (action.help, action.metavar, tuple(action.choices) if action.choices else None) == \
        (how.help, how.metavar, how.choices)


def test_ipcosim_run_takes_only_fields_of_run_options() -> None:
    fields = {f.name for f in dataclasses.fields(RunOptions)}
    named = set(inspect.signature(ipcosim.run).parameters) - EXTENSION_POINTS
    assert named - fields == set(), "ipcosim.run names an option that is not a field of RunOptions"
    # RunOptions.create spells no option of its own: its keywords are the fields
    create = inspect.signature(RunOptions.create).parameters
    assert [p.kind for p in create.values()] == [inspect.Parameter.POSITIONAL_OR_KEYWORD,
                                                 inspect.Parameter.VAR_KEYWORD]


def test_a_prepared_run_spells_no_option_of_its_own() -> None:
    """Prepared.run and Prepared.execution take a RunOptions and its fields by name; Prepared's keywords
    that are options are the fields of the load stage, by the same names."""
    for method, own in ((Prepared.run, {"observers", "manipulators", "raise_on_error"}),
                        (Prepared.execution, {"observers", "manipulators", "started"})):
        parameters = inspect.signature(method).parameters
        assert set(parameters) == {"self", "options", "fields"} | own
        assert parameters["fields"].kind == inspect.Parameter.VAR_KEYWORD
    load = {name for name, how in run_options() if how.stage == "load"} - {"scenario"}
    assert load <= set(inspect.signature(Prepared).parameters)


def test_an_option_of_no_stage_is_refused_where_it_is_declared() -> None:
    from ipcosim.harness.api.options import STAGES, Option

    assert {how.stage for _, how in run_options()} == set(STAGES)  # every stage takes some option
    with pytest.raises(ValueError, match="--stop-time: stage 'runs', expected one of load, run, command"):
        Option("--stop-time", "Stop time [s].", lambda flag, value: value, stage="runs")


@pytest.mark.parametrize(("name", "value", "message"), [
    ("swap", {"plant": "hil"}, "swap: an option of prepare(), not of each run of a prepared scenario"),
    ("timeout", 5, "timeout: an option of ipcosim.run(), not of each run of a prepared scenario"),
    ("stoptime", 1.0, "stoptime: not an option of a run; did you mean"),
    ("stop_time", -1, "--stop-time -1: must be a positive number of seconds")])
def test_a_prepared_run_refuses_what_is_not_its_option(name: str, value: object, message: str) -> None:
    factory = loop_factory()
    with pytest.raises(UsageError) as refused:
        Prepared(system=loop_system(), slave_factory=factory, warn=False).run(**{name: value})
    assert str(refused.value).startswith(message)
    assert factory.slaves == {}  # refused before anything was instantiated


def test_a_prepared_run_takes_the_options_object(tmp_path) -> None:
    options = RunOptions("loop", stop_time=0.05, step=0.01, record=["plant.*"], out=tmp_path / "given")
    prepared = Prepared(system=loop_system(), slave_factory=loop_factory(), warn=False)
    given = prepared.run(options)
    overridden = prepared.run(options, stop_time=0.02, out=tmp_path / "overridden")
    for folder in ("given", "overridden"):
        header = (tmp_path / folder / "results.csv").read_text().splitlines()[0]
        assert header == "time,plant.voltage,plant.position"  # the loop plant's connectors, in its order
    assert (given.data["time"][-1], overridden.data["time"][-1]) == pytest.approx((0.05, 0.02))


def test_every_option_ipcosim_run_documents_is_a_field() -> None:
    doc = inspect.getdoc(ipcosim.run) or ""
    more = doc.split("**more", 1)[1].split("Returns", 1)[0]
    named = {w.strip("`") for w in more.replace(",", " ").replace("(", " ").replace(")", " ").split()
             if w.startswith("``") and w.endswith("``")}
    fields = {f.name for f in dataclasses.fields(RunOptions)}
    assert named and named <= fields


def test_the_docstring_describes_every_field() -> None:
    doc = RunOptions.__doc__ or ""
    for name, how in run_options():
        assert f"    {name} : " in doc and how.help[1:] in doc


# The messages ipcosim.run and ipcosim run give for a bad value: docs/api.md's doctest for --stop-time,
# the ranges the options' help states for the others.
BAD = [("stop_time", "--stop-time", "-1", "--stop-time -1: must be a positive number of seconds"),
       ("step", "--step", "0", "--step 0: must be a positive number of seconds"),
       ("timeout", "--timeout", "soon", "--timeout 'soon': not a number of seconds"),
       ("overrun_budget", "--overrun-budget", "1.5", "--overrun-budget 1.5: expected a fraction in [0, 1]"),
       ("live_port", "--live-port", "70000", "--live-port 70000: expected a port number 0..65535"),
       ("swap", "--swap", "plant", "--swap 'plant': expected COMPONENT=FMU_OR_ALIAS")]


@pytest.mark.parametrize(("name", "flag", "value", "message"), BAD)
def test_a_bad_value_fails_the_same_way_from_python_and_the_command_line(
        name: str, flag: str, value: str, message: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(UsageError) as python:
        RunOptions("single-mass-lqr", **{name: [value] if name == "swap" else value})
    assert str(python.value).startswith(message)
    assert cli.main(["run", "single-mass-lqr", flag, value]) == cli.EXIT_USAGE
    assert capsys.readouterr().err.strip() == f"ipcosim run: error: {python.value}"


def test_the_command_line_defaults_are_the_documented_ones() -> None:
    """docs/api.md: the command line writes into out/<scenario> by default and shows its progress; a
    Python run writes nothing and shows none; neither forces real-time pacing (None: when a component asks)."""
    from_cli = RunOptions.from_args(_run_parser().parse_args(["ssp/single-mass-lqr/SystemStructure.ssd"]))
    from_python = RunOptions("ssp/single-mass-lqr/SystemStructure.ssd")
    assert (str(from_cli.out), from_cli.progress, from_cli.realtime) == ("out/single-mass-lqr", True, None)
    assert (from_python.out, from_python.progress, from_python.realtime) == (None, False, None)
    assert dataclasses.replace(from_cli, out=None, progress=False) == from_python


def test_metrics_json_is_written_once_with_the_final_figures(tmp_path, monkeypatch) -> None:
    writes: list[dict] = []
    original = Result.write_metrics

    def counting(self: Result, path) -> None:
        original(self, path)
        writes.append(json.loads(path.read_text()))

    monkeypatch.setattr(Result, "write_metrics", counting)
    result = Prepared(system=loop_system(), slave_factory=loop_factory(), warn=False).run(
        stop_time=0.05, step=0.01, out=tmp_path / "run", raise_on_error=False)
    assert len(writes) == 1
    assert writes[0]["wall_time_s"] == result.metrics["wall_time_s"] == result.metadata["wall_time_s"]
    assert result.metadata["files"]["metrics"] == str(tmp_path / "run" / "metrics.json")


def test_a_sweep_loads_and_binds_its_scenario_once_and_parses_vary_once(tmp_path, monkeypatch) -> None:
    from ipcosim.harness.api import engine, grammar
    from ipcosim.harness.studies.robustness import sweep_study

    calls = {"bind": 0, "parse_all": 0}

    def counted(module, name):
        original = getattr(module, name)

        def wrapper(*args, **kwargs):
            calls[name] += 1
            return original(*args, **kwargs)
        monkeypatch.setattr(module, name, wrapper)

    counted(engine, "bind")
    counted(grammar, "parse_all")
    study = sweep_study("single-mass-lqr", ["plant.Mp=grid(0.1,0.2,2)"], fmus="python", out=tmp_path / "sweep")
    assert calls == {"bind": 1, "parse_all": 1}
    assert [v.name for v in study.varies] == ["plant.Mp"]
