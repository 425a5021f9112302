"""Every FMU declares a DefaultExperiment, so that another tool's defaults run it meaningfully:
fmpy's ``simulate_fmu`` with no options steps it at the declared step size (its sample period,
for a controller) to the declared stop time, one row per step; a controller alone answers its
inputs."""
from __future__ import annotations

import zipfile
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy")

pytestmark = pytest.mark.integration


def _experiment(fmu: Path) -> tuple[dict[str, str], float | None]:
    """The DefaultExperiment's attributes and the start value of ``sample_period`` (if any)."""
    with zipfile.ZipFile(fmu) as zf:
        root = ElementTree.fromstring(zf.read("modelDescription.xml"))
    exp = root.find("DefaultExperiment")
    assert exp is not None, f"{fmu.name}: no DefaultExperiment"
    period = None
    for v in root.iter():
        if v.get("name") == "sample_period":
            start = v.get("start") if v.get("start") is not None else next(iter(v), v).get("start")
            period = float(start)
    return dict(exp.attrib), period


def _fmus(folder: Path) -> list[Path]:
    # The HIL adapters stand for the rig: without a rig server to talk to they refuse to initialize.
    return sorted(p for p in folder.glob("*.fmu") if "HIL" not in p.stem)


def _check_default_run(fmu: Path, exact_step: bool = True) -> None:
    exp, period = _experiment(fmu)
    step = float(exp["stepSize"])
    if exact_step:
        assert step == (period if period is not None else 1e-3), (fmu.name, exp)
    assert float(exp["startTime"]) == 0.0 and float(exp["stopTime"]) > 0
    result = fmpy.simulate_fmu(str(fmu))  # fmpy's defaults: the DefaultExperiment
    assert len(result) > 1, fmu.name
    spacing = np.diff(result["time"])
    if exact_step:  # every step the declared one
        assert np.allclose(spacing, step, rtol=1e-9), fmu.name
    else:  # whole multiples of it (fmpy's output interval at most 1000 rows)
        assert np.allclose(spacing / step, np.round(spacing / step), atol=1e-6) and np.all(spacing >= step * 0.999)
    assert result["time"][-1] == pytest.approx(float(exp["stopTime"]))


def test_every_python_fmu_runs_with_fmpys_defaults(native_fmus):
    fmus = _fmus(native_fmus[0])
    assert len(fmus) >= 10
    for fmu in fmus:
        _check_default_run(fmu)


@pytest.mark.parametrize("fmi", ["2", "3"])
def test_every_native_fmu_runs_with_fmpys_defaults(native_fmus, native_fmus3, fmi):
    fmus = _fmus(native_fmus[1] if fmi == "2" else native_fmus3)
    assert len(fmus) >= 10
    for fmu in fmus:
        _check_default_run(fmu)


def test_an_exported_loop_runs_with_fmpys_defaults(native_fmus, tmp_path):
    from ipcosim.harness.api.export import ExportOptions, export

    out = export(ExportOptions("single-mass-lqr", tmp_path / "Loop.fmu", None, None, (native_fmus[1],), {}, "2"))
    exp, _ = _experiment(out)
    assert (float(exp["stepSize"]), float(exp["stopTime"])) == (1e-3, 10.0)  # the scenario's step and stop time
    _check_default_run(out, exact_step=False)  # the loop steps its components inside any communication step


@pytest.mark.parametrize("flavour", [0, 1], ids=["python", "native"])
def test_a_controller_alone_answers_its_inputs(native_fmus, flavour):
    fmu = native_fmus[flavour] / "LQRSingleMass.fmu"
    step_at = 0.3
    inputs = np.array([(0.0, 0.0), (step_at, 0.0), (step_at, 0.05), (1.0, 0.05)],
                      dtype=[("time", float), ("reference", float)])
    result = fmpy.simulate_fmu(str(fmu), input=inputs, output=["voltage"])  # the default 1 s at 1 ms
    before, after = result["voltage"][result["time"] < step_at], result["voltage"][result["time"] > step_at + 0.01]
    # measured positions 0 at the reference 0: the equilibrium, no voltage; a new reference: a voltage
    assert np.all(before == 0.0)
    assert np.all(np.abs(after) > 0.0)
