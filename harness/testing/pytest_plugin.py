"""The ``ipcosim`` pytest plugin (entry point ``pytest11``; inert unless a test uses it).

Fixtures
--------
``ipcosim_fmus`` (session)
    Builds the project's FMUs once per session (``ipcosim.build()``; an FMU whose sources
    are unchanged is not rebuilt) and returns their folder.
``cosim``
    ``cosim.run(scenario, swap=..., set=..., stop_time=...)`` is :func:`ipcosim.run` with
    each run's ``results.csv`` and ``metrics.json`` kept under the test's ``tmp_path``
    (``run-01-<scenario>/``...); a failing test's report lists those folders and metrics.
``ipcosim_rig``
    The ``--ipcosim-rig URI`` card URI; a test that uses it is skipped without the option.

Marker ``ipcosim_hil``: the test needs a rig; skipped (with the reason) without ``--ipcosim-rig``.

Importing this module costs nothing but pytest: ipcosim's master loads on first use.
"""
from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import pytest

HIL_MARKER = "ipcosim_hil"
NO_RIG = "needs a rig: run pytest with --ipcosim-rig URI (e.g. q4:0@tcpip://127.0.0.1:18920)"


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("ipcosim", "ipcosim co-simulation")
    group.addoption("--ipcosim-rig", metavar="URI", default=None,
                    help="card URI of a rig for tests marked ipcosim_hil (without it they are skipped)")


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", f"{HIL_MARKER}: hardware-in-the-loop test; {NO_RIG}")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if config.getoption("--ipcosim-rig"):
        return
    for item in items:
        if item.get_closest_marker(HIL_MARKER):
            item.add_marker(pytest.mark.skip(reason=NO_RIG))


class Cosim:
    """Runs scenarios for one test; every run's files go to ``tmp_path/run-NN-<scenario>``."""

    def __init__(self, tmp_path: Path, rig: str | None) -> None:
        self.tmp_path = tmp_path
        self.rig = rig
        self.runs: list[tuple[Path, Any]] = []

    def run(self, scenario: str, **options: Any) -> Any:
        """:func:`ipcosim.run` with ``out`` under the test's ``tmp_path`` (see its parameters)."""
        __tracebackhide__ = True
        import ipcosim
        from ipcosim.harness.api.options import scenario_label

        out = self.tmp_path / f"run-{len(self.runs) + 1:02d}-{scenario_label(scenario)}"
        options.setdefault("out", out)
        self.runs.append((Path(options["out"]), None))
        try:
            result = ipcosim.run(scenario, **options)
        except ipcosim.SimulationError as exc:
            self.runs[-1] = (Path(options["out"]), exc.result)
            raise
        self.runs[-1] = (Path(options["out"]), result)
        return result

    def report(self) -> str:
        """The runs of this test: folder and main metrics, one line each."""
        lines = []
        for out, result in self.runs:
            if result is None:
                lines.append(f"{out}: no result (the run raised)")
                continue
            m = result.metrics
            keys = ("upright", "settling_time_s", "steady_state_error_m", "max_abs_angle_rad", "peak_voltage_V",
                    "cart_mean_error_m", "cart_peak_to_peak_m", "limit_cycle")
            text = ", ".join(f"{k}={m.get(k)!r}" if not isinstance(m.get(k), float) else f"{k}={m[k]:.4g}"
                             for k in keys if k in m)
            if "cart_mean_error_m" in m:  # the sweeps' success criterion (docs/metrics.md)
                from ipcosim.fmus.metrics import success_status

                text += f", task={success_status(m, result.metadata.get('amplitude_bound_m'))}"
            lines.append(f"{out}: {text}" + ("" if result.ok else f" FAILED: {result.error}"))
        return "\n".join(lines)


@pytest.fixture(scope="session")
def ipcosim_fmus() -> Path:
    """The folder of the project's FMUs, built once per session (unchanged FMUs are kept)."""
    import ipcosim

    fmus = ipcosim.build()
    return fmus[0].parent


@pytest.fixture
def ipcosim_rig(request: pytest.FixtureRequest) -> str:
    """The rig's card URI from ``--ipcosim-rig``; skips the test without it."""
    uri = request.config.getoption("--ipcosim-rig")
    if not uri:
        pytest.skip(NO_RIG)
    return uri


@pytest.fixture
def cosim(request: pytest.FixtureRequest, tmp_path: Path, ipcosim_fmus: Path) -> Cosim:
    """Runs scenarios (``cosim.run(...)``, as :func:`ipcosim.run`) with results kept under ``tmp_path``."""
    runner = Cosim(tmp_path, request.config.getoption("--ipcosim-rig"))
    request.node.stash[_COSIM_KEY] = runner
    return runner


_COSIM_KEY = pytest.StashKey[Cosim]()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Any:
    outcome = yield
    report = outcome.get_result()
    if report.failed and call.excinfo is not None and _is_setup_error(call.excinfo.value):
        report.longrepr = _one_line(item, call.excinfo)
    runner = item.stash.get(_COSIM_KEY, None)
    if runner is not None and runner.runs and report.failed:
        report.sections.append(("ipcosim runs (results.csv, metrics.json)", runner.report()))



def _is_setup_error(exc: BaseException) -> bool:
    """An ipcosim error about the inputs (option, scenario, FMU): not a failed check or run."""
    errors = sys.modules.get("ipcosim.errors")
    testing = sys.modules.get("ipcosim.harness.testing")
    results = sys.modules.get("ipcosim.harness.master.results")
    if errors is None or not isinstance(exc, errors.IpcosimError):
        return False
    checked = testing is not None and isinstance(exc, testing.CheckFailed)
    failed_run = results is not None and isinstance(exc, results.SimulationError)
    return not (checked or failed_run)


def _one_line(item: pytest.Item, excinfo: pytest.ExceptionInfo[BaseException]) -> str:
    """``test_file.py:LINE: ErrorClass: message``, the line of the test that made the call."""
    here = [e for e in excinfo.traceback if str(e.path) == str(item.path)]
    where = f"{item.path}:{here[-1].lineno + 1}" if here else item.nodeid
    return f"{where}: {type(excinfo.value).__name__}: {excinfo.value}"
