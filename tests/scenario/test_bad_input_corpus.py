"""The bad-input corpus of ``ipcosim run``: archives, SSD/SSV files, command-line values,
parameter values, FMU faults, signals and output folders.

Every case asserts one clear error line naming the file, component or value, the exit
status, what is on disk afterwards (partial results where a run had started), every FMU
instance freed, and an empty temporary folder. Cases are tables run in-process; the signal
cases run as subprocesses, started together.
"""
from __future__ import annotations

import os
import shutil
import stat
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import pytest
from ssd_helpers import component, connection, connector, ssd, ssv, write_scenario

from ipcosim.harness import cli

pytestmark = pytest.mark.integration
DATA = Path(__file__).resolve().parents[1] / "data"


# ------------------------------------------------------------------ fixtures
@pytest.fixture(scope="session")
def corpus_fmus(tmp_path_factory) -> dict[str, Path]:
    from ipcosim.fmus.pybuild import build_all

    out = tmp_path_factory.mktemp("corpus-fmus")
    scripts = [DATA / "fmu_master_source.py", DATA / "fmu_master_gain.py", DATA / "fmu_corpus_fault.py"]
    return {r.fmu.stem: r.fmu for r in build_all(out, scripts=scripts)}


@pytest.fixture
def tmpdir_watch(tmp_path, monkeypatch) -> Path:
    """A private temporary folder for the run (checked empty by :func:`check_clean`)."""
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    monkeypatch.setenv("TMPDIR", str(tmp))
    return tmp


SRC = lambda **inline: component("src", "MasterSource", [connector("y", "output")], inline=inline or None)  # noqa: E731
GAIN = component("g", "MasterGain", [connector("u", "input"), connector("aux", "input", "rad"),
                                     connector("y", "output"), connector("z", "output", "rad")])
FAULT = lambda **inline: component("f", "CorpusFault", [connector("u", "input"), connector("y", "output")],  # noqa: E731
                                   inline=inline or None)
CONNS = [connection("src.y", "g.u")]


def scenario(tmp_path: Path, fmus, comps=None, conns=None, name="s", **kw) -> Path:
    text = ssd(name, comps if comps is not None else [SRC(), GAIN], CONNS if conns is None else conns, **kw)
    return write_scenario(tmp_path / name, text, fmus)


def run_cli(capsys, *argv: object) -> tuple[int, list[str]]:
    rc = cli.main(["run", *map(str, argv), "--quiet"])
    err = capsys.readouterr().err
    return rc, [line for line in err.splitlines() if line.strip()]


def error_line(err: list[str]) -> str:
    """The one error line (warnings aside)."""
    errors = [line for line in err if "warning:" not in line]
    assert len(errors) == 1, err
    assert errors[0].startswith("ipcosim run: error: "), errors
    return errors[0]


def check_clean(tmp: Path, tracked=None) -> None:
    """Nothing left in the temporary folder; every instantiated FMU freed."""
    assert list(tmp.iterdir()) == []
    if tracked is not None:
        made, freed = tracked
        assert set(map(id, freed)) == set(map(id, made))


def read_csv(path: Path) -> np.ndarray:
    return np.genfromtxt(path, delimiter=",", names=True, deletechars="")


# ------------------------------------------------------------------ archives
def _pack(folder: Path, archive: Path, extra: dict[str, bytes] | None = None, source: str | None = None,
          infos: list[tuple[zipfile.ZipInfo, bytes]] = ()) -> Path:
    """Zip a scenario folder into ``archive``; ``source`` replaces the FMU source of component g."""
    with zipfile.ZipFile(archive, "w") as zf:
        for p in sorted(folder.rglob("*")):
            if p.is_file():
                data = p.read_bytes()
                if p.name == "SystemStructure.ssd" and source is not None:
                    data = data.replace(b'source="resources/MasterGain.fmu"', f'source="{source}"'.encode())
                zf.writestr(p.relative_to(folder).as_posix(), data)
        for name, data in (extra or {}).items():
            zf.writestr(name, data)
        for info, data in infos:
            zf.writestr(info, data)
    return archive


def _fmu_with(fmu: Path, out: Path, name: str, data: bytes, mode: int | None = None) -> Path:
    """A copy of ``fmu`` with one extra member (``mode``: Unix file type and permissions)."""
    shutil.copyfile(fmu, out)
    info = zipfile.ZipInfo(name)
    if mode is not None:
        info.create_system = 3
        info.external_attr = mode << 16
    with zipfile.ZipFile(out, "a") as zf:
        zf.writestr(info, data)
    return out


ESCAPES = {
    "dotdot-source": ("../../escaped.fmu", "'..' in the name"),
    "dotdot-inside-source": ("resources/../../../escaped.fmu", "'..' in the name"),
    "absolute-source": ("/tmp/ipcosim-escaped.fmu", "absolute name"),
    "backslash-source": ("..\\..\\escaped.fmu", "absolute name or drive letter"),
}


@pytest.mark.parametrize("case", sorted(ESCAPES))
def test_archive_component_source_escaping_the_folder(case, tmp_path, capsys, corpus_fmus, tmpdir_watch, tracked):
    source, reason = ESCAPES[case]
    folder = scenario(tmp_path, corpus_fmus)
    member = source.replace("\\", "/").lstrip("/")
    arch = _pack(folder, tmp_path / "evil.ssp", extra={member: corpus_fmus["MasterGain"].read_bytes()}, source=source)
    rc, err = run_cli(capsys, arch, "--out", tmp_path / "out")
    line = error_line(err)
    assert rc == 1 and "evil.ssp: member" in line and repr(source) in line and reason in line
    assert not (tmp_path / "escaped.fmu").exists() and not Path("/tmp/ipcosim-escaped.fmu").exists()
    assert tracked[0] == [] and not (tmp_path / "out").exists()
    check_clean(tmpdir_watch, tracked)


FMU_MEMBERS = {
    "fmu-dotdot-member": ("../../outside.txt", None, "'..' in the name"),
    "fmu-absolute-member": ("/tmp/ipcosim-outside.txt", None, "absolute name"),
    "fmu-symlink-member": ("resources/link", stat.S_IFLNK | 0o777, "symbolic link"),
    "fmu-device-member": ("resources/dev", stat.S_IFCHR | 0o666, "device or special file"),
    "fmu-fifo-member": ("resources/fifo", stat.S_IFIFO | 0o666, "device or special file"),
}


@pytest.mark.parametrize("case", sorted(FMU_MEMBERS))
def test_fmu_member_refused(case, tmp_path, capsys, corpus_fmus, tmpdir_watch, tracked):
    name, mode, reason = FMU_MEMBERS[case]
    bad = _fmu_with(corpus_fmus["MasterGain"], tmp_path / "MasterGain.fmu", name, b"/etc/passwd", mode)
    folder = scenario(tmp_path, {"MasterSource": corpus_fmus["MasterSource"], "MasterGain": bad})
    rc, err = run_cli(capsys, folder, "--out", tmp_path / "out")
    line = error_line(err)
    assert rc == 1 and "MasterGain.fmu: member" in line and repr(name) in line and reason in line
    assert not (tmp_path / "outside.txt").exists() and not Path("/tmp/ipcosim-outside.txt").exists()
    assert tracked[0] == []
    check_clean(tmpdir_watch, tracked)


def test_fmu_in_an_archive_with_a_symlink_member(tmp_path, capsys, corpus_fmus, tmpdir_watch, tracked):
    bad = _fmu_with(corpus_fmus["MasterGain"], tmp_path / "bad.fmu", "binaries/x", b"/", stat.S_IFLNK | 0o777)
    folder = scenario(tmp_path, {"MasterSource": corpus_fmus["MasterSource"], "MasterGain": bad})
    arch = _pack(folder, tmp_path / "linked.ssp")
    rc, err = run_cli(capsys, arch)
    line = error_line(err)
    assert rc == 1 and "MasterGain.fmu: member 'binaries/x': symbolic link" in line
    check_clean(tmpdir_watch, tracked)


def test_archive_with_too_many_members(tmp_path, capsys, corpus_fmus, tmpdir_watch, monkeypatch):
    from ipcosim.harness.scenario import archive

    monkeypatch.setattr(archive, "MAX_MEMBERS", 5)
    folder = scenario(tmp_path, corpus_fmus)
    rc, err = run_cli(capsys, folder)
    line = error_line(err)
    assert rc == 1 and "MasterSource.fmu: " in line and "more than the limit 5" in line
    check_clean(tmpdir_watch)


def test_archive_member_larger_than_declared_is_stopped(tmp_path, capsys, corpus_fmus, tmpdir_watch, monkeypatch):
    from ipcosim.harness.scenario import archive

    monkeypatch.setattr(archive, "MAX_TOTAL_BYTES", 4096)
    folder = scenario(tmp_path, corpus_fmus)
    rc, err = run_cli(capsys, folder)
    line = error_line(err)
    assert rc == 1 and "MasterSource.fmu: " in line and "more than the limit 4096" in line
    check_clean(tmpdir_watch)


def test_good_archive_still_runs(tmp_path, capsys, corpus_fmus, tmpdir_watch, tracked):
    folder = scenario(tmp_path, corpus_fmus, comps=[SRC(value=3.0), GAIN])
    arch = _pack(folder, tmp_path / "good.ssp")
    rc, err = run_cli(capsys, arch, "--out", tmp_path / "out")
    assert rc == 0, err
    assert np.all(read_csv(tmp_path / "out" / "results.csv")["g.y"] == 6.0)
    assert len(tracked[0]) == 2
    check_clean(tmpdir_watch, tracked)


# ------------------------------------------------------------------ SSD and SSV files
def _edit(folder: Path, old: str, new: str, name: str = "SystemStructure.ssd") -> None:
    path = folder / name
    text = path.read_text()
    assert old in text, old
    path.write_text(text.replace(old, new, 1))


SSD_CASES = {
    # case: (edit of the SSD: old, new), expected text in the error line
    "infinite-stop-time": (('stopTime="1.0"', 'stopTime="INF"'),
                           "SystemStructure.ssd: DefaultExperiment stopTime inf: not a finite number"),
    "absurd-stop-time": (('stopTime="1.0"', 'stopTime="1e300"'),
                         "SystemStructure.ssd: DefaultExperiment stopTime 1e+300 s at"),
    "stop-before-start": (('startTime="0.0"', 'startTime="5.0"'), "stopTime 1 s must be after startTime 5 s"),
    "zero-base-step": (('baseStepSize="0.01"', 'baseStepSize="0"'), "baseStepSize 0 must be positive"),
    "nan-base-step": (('baseStepSize="0.01"', 'baseStepSize="NaN"'), "baseStepSize nan must be positive"),
    "tiny-base-step": (('baseStepSize="0.01"', 'baseStepSize="1e-300"'), "more than the limit"),
    "duplicate-component": (('<ssd:Component name="g"', '<ssd:Component name="src"'),
                            "duplicate component name 'src'"),
    "unknown-connection-end": (('endElement="g"', 'endElement="nobody"'),
                               "connection names component 'nobody'"),
    "missing-binding-file": (('<ssd:Connectors>', '<ssd:Connectors>', ), None),
    "not-well-formed": (("</ssd:System>", "</ssd:Sys>"), "SystemStructure.ssd"),
    "bad-linear-transformation": (('<ssd:Connection startElement="src" startConnector="y" endElement="g" '
                                   'endConnector="u"/>',
                                   '<ssd:Connection startElement="src" startConnector="y" endElement="g" '
                                   'endConnector="u"><ssc:LinearTransformation factor="INF"/></ssd:Connection>'),
                                  "linear transformation factor/offset must be finite"),
}
SSD_CASES.pop("missing-binding-file")


@pytest.mark.parametrize("case", sorted(SSD_CASES))
def test_bad_ssd(case, tmp_path, capsys, corpus_fmus, tmpdir_watch, tracked):
    (old, new), expected = SSD_CASES[case]
    folder = scenario(tmp_path, corpus_fmus)
    _edit(folder, old, new)
    rc, err = run_cli(capsys, folder, "--out", tmp_path / "out")
    line = error_line(err)
    assert rc == 1 and expected in line, line
    assert tracked[0] == [] and not (tmp_path / "out" / "results.csv").exists()
    check_clean(tmpdir_watch, tracked)


SSV_CASES = {
    # case: (.ssv text, expected text in the error line)
    "nan-parameter": (ssv("bad", {"gain": 1.0}).replace('value="1.0"', 'value="NaN"'), "gain"),
    "unknown-parameter": (ssv("bad", {"nothing": 1.0}), "nothing"),
    "not-well-formed": ("<ssv:ParameterSet", "bad.ssv"),
    "string-for-real": (ssv("bad", {"gain": 1.0}).replace('value="1.0"', 'value="fast"'), "bad.ssv"),
    "fails-schema": (ssv("bad", {"gain": 1.0}).replace("<ssv:Parameters>", "<ssv:Bogus/><ssv:Parameters>"),
                     "bad.ssv"),
}


@pytest.mark.parametrize("case", sorted(SSV_CASES))
def test_bad_ssv(case, tmp_path, capsys, corpus_fmus, tmpdir_watch, tracked):
    text, expected = SSV_CASES[case]
    gain = component("g", "MasterGain", [connector("u", "input"), connector("aux", "input", "rad"),
                                         connector("y", "output"), connector("z", "output", "rad")],
                     bindings=["bad.ssv"])
    folder = write_scenario(tmp_path / "s", ssd("s", [SRC(), gain], CONNS), corpus_fmus, {"bad.ssv": text})
    rc, err = run_cli(capsys, folder, "--out", tmp_path / "out")
    line = error_line(err)
    assert rc == 1 and expected in line, line
    check_clean(tmpdir_watch, tracked)


# ------------------------------------------------------------------ command-line values
CLI_CASES = {
    "negative-step-exponent": (("--step", "-1e-3"), "--step -1e-3: must be a positive number of seconds"),
    "negative-stop-exponent": (("--stop-time", "-1e-3"), "--stop-time -1e-3: must be a positive number"),
    "infinite-stop": (("--stop-time", "inf"), "--stop-time inf: must be a positive number"),
    "nan-step": (("--step", "nan"), "--step nan: must be a positive number"),
    "absurd-stop": (("--stop-time", "1e300"), "baseStepSize 0.01 s: 1e+302 steps, more than the limit"),
    "absurd-small-step": (("--step", "1e-300"), "steps, more than the limit"),
    "unknown-record": (("--record", "g.nothing"), "--record g.nothing: no such variable"),
    "unknown-parameter-set": (("--parameter-set", "nothing"), "nothing"),
    "zero-timeout": (("--timeout", "0"), "--timeout 0: must be a positive number"),
    "negative-timeout": (("--timeout", "-5e0"), "--timeout -5e0: must be a positive number"),
    "set-empty-value": (("--set", "g.gain="), "--set 'g.gain=': expected COMPONENT.VARIABLE=VALUE"),
    "set-without-variable": (("--set", "g=1"), "expected COMPONENT.VARIABLE=VALUE"),
    "swap-missing-file": (("--swap", "g=missing.fmu"), "--swap g=missing.fmu"),
}


@pytest.mark.parametrize("case", sorted(CLI_CASES))
def test_bad_command_line_value(case, tmp_path, capsys, corpus_fmus, tmpdir_watch, tracked):
    args, expected = CLI_CASES[case]
    folder = scenario(tmp_path, corpus_fmus)
    rc, err = run_cli(capsys, folder, *args, "--out", tmp_path / "out")
    line = error_line(err)
    # a command-line mistake exits 2; a run the engine cannot carry out (more steps than its limit) 1
    assert rc == (1 if case.startswith("absurd") else 2) and expected in line, line
    assert tracked[0] == [] and not (tmp_path / "out").exists()
    check_clean(tmpdir_watch, tracked)


def test_ssd_external_entity_is_not_read(tmp_path, capsys, corpus_fmus, tmpdir_watch, tracked):
    folder = scenario(tmp_path, corpus_fmus)
    secret = tmp_path / "secret.txt"
    secret.write_text("top-secret-text")
    _edit(folder, '<?xml version="1.0" encoding="UTF-8"?>\n<ssd:SystemStructureDescription',
          f'<?xml version="1.0" encoding="UTF-8"?>\n<!DOCTYPE x [<!ENTITY e SYSTEM "file://{secret}">]>\n'
          f'<ssd:SystemStructureDescription')
    _edit(folder, '<ssd:System name="s">', '<ssd:System name="s" description="&e;">')
    rc, err = run_cli(capsys, folder, "--out", tmp_path / "out")
    line = error_line(err)
    assert rc == 1 and "SystemStructure.ssd" in line and "top-secret-text" not in line
    check_clean(tmpdir_watch, tracked)


# ------------------------------------------------------------------ subprocess cases: FMU faults, parameter
# values, signals. pythonfmu 0.7.0 releases objects twice after a Python exception in an FMU (see
# ipcosim.fmus.fmi), so fatal FMU errors run in their own processes; signals need their own process
# anyway. All start together and run in parallel (a few at a time).
import json  # noqa: E402
import signal  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass, field, replace  # noqa: E402

RUNNER = DATA / "corpus_runner.py"
PARALLEL = 4


@dataclass
class Case:
    comps: dict = field(default_factory=dict)   # inline parameters of f (CorpusFault)
    args: tuple = ()
    status: int = 1
    line: str = ""                              # expected in the one error line ("" : no error line)
    last_time: float | None = None              # time of the last results row
    min_rows: int = 1                           # at least this many rows in results.csv
    signal_at: str = ""                         # CORPUS_SIGNAL_AT
    send: tuple = ()                            # (signal, rows in results.csv before it is sent)
    freed: bool = True                          # every instance freed (counted by the runner)
    clean: bool = True                          # nothing left in the temporary folder
    stop: float = 1.0


SLOW = {"fault": 5, "delay": 0.01}
SUBPROCESS_CASES = {
    # FMU faults
    "fault-exception": Case({"fault": 1, "fail_time": 0.5}, line="component f (CorpusFault): fmi2DoStep returned "
                            "fmi2Fatal at t = 0.5 s: RuntimeError: corpus fault: exploded at t = 0.5 s", last_time=0.5),
    "fault-nan-output": Case({"fault": 2, "fail_time": 0.5},
                             line="component f (CorpusFault): output f.y = nan at t = 0.51 s", last_time=0.51),
    "fault-discard": Case({"fault": 3, "fail_time": 0.5}, line="fmi2DoStep returned fmi2Discard at t = 0.5 s: "
                          "corpus fault: cannot step from t = 0.5 s", last_time=0.5),
    "fault-exception-in-initialization": Case({"fault": 6}, line="component f (CorpusFault): "
                                              "fmi2ExitInitializationMode returned fmi2Fatal", min_rows=0),
    # the rows of the chunk that hangs (at most CHUNK_SECONDS of wall time) are not written
    "fault-hang-past-timeout": Case({"fault": 4, "fail_time": 0.3}, args=("--timeout", "5"), status=124,
                                    line="wall-clock limit of 5 s reached and an FMU call did not return",
                                    min_rows=1, freed=False),
    "fault-slow-past-timeout": Case(dict(SLOW), args=("--timeout", "2"), status=124, stop=1000.0,
                                    line="stopped: wall-clock limit (--timeout) reached at t =", min_rows=20),
    # parameter values
    "parameter-nan": Case(args=("--set", "g.gain=nan"), line="gain", min_rows=0),
    "parameter-infinite": Case(args=("--set", "g.gain=1e400"), line="gain", min_rows=0),
    "parameter-negative-delay": Case(args=("--set", "f.fail_time=-inf"), line="fail_time", min_rows=0),
    "parameter-bad-period": Case(args=("--set", "g.sample_period=-0.01"), line="g.sample_period", min_rows=-1),
    "parameter-not-an-integer": Case(args=("--set", "f.fault=1.5"), status=2, line="f.fault", min_rows=-1),
    # signals at every phase
    # before the run starts (no FMU code running) the command stops at once, nothing written
    "sigterm-load": Case(signal_at="load:SIGTERM", status=143, line="interrupted by SIGTERM; nothing was written",
                         min_rows=-1),
    "sigint-load": Case(signal_at="load:SIGINT", status=130, line="interrupted by SIGINT; nothing was written",
                        min_rows=-1),
    "sigterm-instantiate": Case(signal_at="instantiate:SIGTERM", status=143, line="interrupted by SIGTERM at t = 0 s",
                                min_rows=0),
    "sigint-initialize": Case(signal_at="initialize:SIGINT", status=130, line="interrupted by SIGINT at t = 0 s",
                              min_rows=0),
    "sigint-inside-initialization": Case({"init_delay": 3.0}, send=(signal.SIGINT, 0), status=130,
                                         line="interrupted by SIGINT at t = 0 s", min_rows=0),
    "sigterm-write": Case(signal_at="write:SIGTERM", status=143, line="interrupted by SIGTERM", last_time=1.0),
    "sigterm-step": Case(dict(SLOW), send=(signal.SIGTERM, 30), status=143, line="interrupted by SIGTERM at t =",
                         min_rows=30, stop=1000.0),
    "sigterm-inside-fmu-call": Case({"fault": 5, "delay": 0.5}, send=(signal.SIGTERM, 2), status=143,
                                    line="interrupted by SIGTERM at t =", min_rows=2, stop=1000.0),
    **{f"sigint-step-{k}": Case(send=(signal.SIGINT, 200 * (k + 1)), status=130, line="interrupted by SIGINT at t =",
                                min_rows=200 * (k + 1), stop=100000.0) for k in range(5)},
    "second-signal-during-cleanup": Case(dict(SLOW), send=(signal.SIGTERM, 30), signal_at="cleanup:SIGTERM",
                                         status=143, line="", min_rows=30, freed=False, stop=1000.0),
    "sigkill-step": Case(dict(SLOW), send=(signal.SIGKILL, 200), status=-9, line="", min_rows=200, freed=False,
                         clean=False, stop=1000.0),
}
# signals while stepping: on the compiled C loop (forced: an error if it could not run), and once on the Python loop
for _name, _case in list(SUBPROCESS_CASES.items()):
    if _case.send or _name.startswith(("sigterm-step", "fault-slow", "fault-hang", "fault-exception")):
        SUBPROCESS_CASES[_name] = replace(_case, args=(*_case.args, "--loop", "c"))
SUBPROCESS_CASES["sigint-step-python-loop"] = replace(SUBPROCESS_CASES["sigint-step-0"], args=("--loop", "python"))


@dataclass
class Outcome:
    status: int
    stderr: str
    out: Path
    tmp: Path
    counts: dict | None
    wall_at_kill: float | None = None
    rows_1s_before_kill: int = 0


def _csv_rows(path: Path) -> int:
    try:
        return max(0, path.read_bytes().count(b"\n") - 1)
    except FileNotFoundError:
        return -1


@pytest.fixture(scope="module")
def subprocess_outcomes(tmp_path_factory, corpus_fmus) -> dict[str, Outcome]:
    root = tmp_path_factory.mktemp("corpus-subprocess")
    comps_src = component("src", "MasterSource", [connector("y", "output")])
    pending = sorted(SUBPROCESS_CASES)
    running: dict[str, tuple] = {}
    outcomes: dict[str, Outcome] = {}
    deadline = time.monotonic() + 300
    while (pending or running) and time.monotonic() < deadline:
        while pending and len(running) < PARALLEL:
            name = pending.pop(0)
            case = SUBPROCESS_CASES[name]
            d = root / name
            (d / "tmp").mkdir(parents=True)
            folder = write_scenario(d / "s", ssd("s", [comps_src, GAIN, FAULT(**case.comps)],
                                                 [connection("src.y", "g.u"), connection("g.y", "f.u")],
                                                 stop=case.stop), corpus_fmus)
            env = dict(os.environ, TMPDIR=str(d / "tmp"), CORPUS_COUNTS=str(d / "counts.json"),
                       CORPUS_SIGNAL_AT=case.signal_at)
            proc = subprocess.Popen([sys.executable, str(RUNNER), "run", str(folder), "--out", str(d / "out"),
                                     "--quiet", *case.args], env=env, stderr=subprocess.PIPE, text=True)
            running[name] = (proc, d, case, [], None)
        for name in list(running):
            proc, d, case, history, killed = running[name]
            csv = d / "out" / "results.csv"
            if case.send and killed is None and proc.poll() is None:
                rows = _csv_rows(csv)
                history.append((time.monotonic(), rows))
                if rows >= case.send[1] and (case.send[1] > 0 or rows >= 0 or (d / "tmp").exists()):
                    if case.send[1] == 0:
                        time.sleep(1.0)  # inside the FMU's initialization (init_delay)
                    proc.send_signal(case.send[0])
                    killed = time.monotonic()
                    running[name] = (proc, d, case, history, killed)
            if proc.poll() is not None:
                err = proc.stderr.read()
                counts = json.loads((d / "counts.json").read_text()) if (d / "counts.json").exists() else None
                before = [r for t, r in history if killed is not None and t <= killed - 1.0]
                outcomes[name] = Outcome(proc.returncode, err, d / "out", d / "tmp", counts, killed,
                                         before[-1] if before else 0)
                del running[name]
        time.sleep(0.05)
    for proc, *_ in running.values():
        proc.kill()
    return outcomes


@pytest.mark.parametrize("name", sorted(SUBPROCESS_CASES))
@pytest.mark.slow
def test_subprocess_case(name, subprocess_outcomes):
    case, got = SUBPROCESS_CASES[name], subprocess_outcomes.get(name)
    assert got is not None, f"{name} did not finish in time"
    assert got.status == case.status, got.stderr
    lines = [line for line in got.stderr.splitlines() if line.strip() and "warning:" not in line]
    if case.line:
        assert len(lines) == 1 and case.line in lines[0], got.stderr
    rows = _csv_rows(got.out / "results.csv")
    if case.min_rows >= 0:
        assert rows >= case.min_rows, (rows, got.stderr)
        data = np.genfromtxt(got.out / "results.csv", delimiter=",", names=True, deletechars="") if rows else None
        if data is not None:
            assert data.size == rows and np.all(np.isfinite(data["time"]))   # every line complete
        if case.last_time is not None:
            assert float(np.atleast_1d(data["time"])[-1]) == pytest.approx(case.last_time, abs=1e-9)
        if case.status != -9 and case.freed:
            assert (got.out / "metrics.json").exists()
    else:
        assert rows == -1  # refused before the run: nothing written
    if case.freed:
        assert got.counts is not None and got.counts["freed"] == got.counts["instantiated"], got.counts
    if case.clean:
        assert list(got.tmp.iterdir()) == []
    if case.send and case.send[0] == signal.SIGKILL:
        # rows reach the disk while the run goes on: at most about a second is lost
        assert rows >= got.rows_1s_before_kill > 0


# ------------------------------------------------------------------ output folders
def _out_under_file(tmp_path: Path) -> Path:
    (tmp_path / "plain-file").write_text("x")
    return tmp_path / "plain-file" / "out"


def _out_is_file(tmp_path: Path) -> Path:
    (tmp_path / "out-file").write_text("x")
    return tmp_path / "out-file"


OUT_CASES = {
    "under-a-file": (_out_under_file, "output folder is not writable (Not a directory)"),
    "is-a-file": (_out_is_file, "is a file, not a folder"),
    "read-only-filesystem": (lambda tmp_path: Path("/proc/ipcosim-out"), "output folder is not writable"),
}


@pytest.mark.parametrize("case", sorted(OUT_CASES))
def test_unwritable_output_folder_is_refused_before_the_run(case, tmp_path, capsys, corpus_fmus, tmpdir_watch,
                                                             tracked):
    make, expected = OUT_CASES[case]
    out = make(tmp_path)
    rc, err = run_cli(capsys, scenario(tmp_path, corpus_fmus), "--out", out)
    line = error_line(err)
    assert rc == 2 and f"--out {out}: {expected}" in line, line  # a usage error: nothing was done
    assert tracked[0] == []  # refused before any FMU was instantiated
    check_clean(tmpdir_watch, tracked)


def test_disk_full_while_running_keeps_the_rows_written(tmp_path, capsys, corpus_fmus, tmpdir_watch, tracked,
                                                        monkeypatch):
    import errno

    from ipcosim.harness.master import results

    real_write, calls = os.write, []

    def full_after_three(fd, data):
        calls.append(len(data))
        if len(calls) > 3:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real_write(fd, data)

    monkeypatch.setattr(results.os, "write", full_after_three)
    rc, err = run_cli(capsys, scenario(tmp_path, corpus_fmus, stop=50.0), "--out", tmp_path / "out")
    monkeypatch.setattr(results.os, "write", real_write)
    line = error_line(err)
    assert rc == 1 and "results.csv: cannot write results (No space left on device)" in line, line
    data = read_csv(tmp_path / "out" / "results.csv")
    assert 1 < data.size < 5001 and f"{data.size} rows written" in line
    assert np.all(np.diff(data["time"]) > 0)
    assert len(tracked[0]) == 2
    check_clean(tmpdir_watch, tracked)
