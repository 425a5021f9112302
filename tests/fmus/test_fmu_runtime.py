"""The FMU runtime on its default path imports only the standard library.

Each FMU is extracted and its script imported from ``resources/`` in a fresh interpreter whose
import system refuses numpy, scipy, python-control, fmpy and the installed ipcosim
(``fmu_runtime_driver.py``); the class is driven as pythonfmu's wrapper drives it. The outputs
must equal, bit for bit, those of the same run without the blocker. A changed design parameter
in such a host fails initialization with one line that names it and points to the gains.
"""
from __future__ import annotations

import json
import subprocess
import sys
import zipfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from ipcosim.fmus.hil.rig import RigConfig, VirtualRig
from ipcosim.fmus.hil.server import RigServer

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]
DRIVER = Path(__file__).resolve().parents[1] / "fmu_runtime_driver.py"
BLOCKED = "numpy,scipy,control,fmpy,ipcosim"
STEPS = 30
LQR_GAINS = [f"K_{s}" for s in ("cart_position", "cart_velocity", "pendulum_angle", "pendulum_velocity")] + \
    ["N"] + [f"M_{s}_{o}" for s in ("cart_position", "cart_velocity", "pendulum_angle", "pendulum_velocity")
             for o in ("cart_position", "pendulum_angle")]


@pytest.fixture(scope="module")
def unzipped_fmus(tmp_path_factory: pytest.TempPathFactory, project_fmus: dict[str, Path]) -> dict[str, Path]:
    """Every FMU of the project (this run's build), extracted: ``{model: folder}``."""
    out = tmp_path_factory.mktemp("runtime-fmus")
    folders = {}
    for fmu in project_fmus.values():
        folder = out / fmu.stem
        with zipfile.ZipFile(fmu) as z:
            z.extractall(folder)
        folders[fmu.stem] = folder
    return folders


def drive(folder: Path, spec: dict, blocked: bool, tmp: Path) -> dict:
    spec_file = tmp / f"{folder.name}-{blocked}-{abs(hash(json.dumps(spec, sort_keys=True)))}.json"
    spec_file.write_text(json.dumps(spec))
    cmd = [sys.executable, str(DRIVER), str(folder), str(spec_file)] + (["--block", BLOCKED] if blocked else [])
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=120, cwd=tmp)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def both(folder: Path, spec: dict, tmp: Path) -> tuple[dict, dict]:
    return drive(folder, spec, True, tmp), drive(folder, spec, False, tmp)


@pytest.mark.slow
def test_every_fmu_runs_on_the_standard_library_alone(unzipped_fmus, tmp_path: Path) -> None:
    models = sorted(m for m in unzipped_fmus if not m.startswith("IP02HIL"))
    from ipcosim.fmus.pybuild import model_scripts
    # every model the build knows (plants, the controllers, the swing-up, the excitations, the setpoint)
    assert models == sorted(m for m in model_scripts() if not m.startswith("IP02HIL"))
    assert {"IP02SingleMass", "LQGDoubleMass", "ExcitationSingleMass", "Setpoint"} <= set(models)
    spec = {"steps": STEPS}
    with ThreadPoolExecutor(max_workers=2) as pool:
        results = dict(zip(models, pool.map(lambda m: both(unzipped_fmus[m], spec, tmp_path), models)))
    for model, (blocked, normal) in results.items():
        assert "error" not in blocked, (model, blocked)
        assert blocked["blocked_attempts"] == [] and blocked["blocked_loaded"] == [], model
        assert blocked["rows"] == normal["rows"], model
        assert len(blocked["rows"]) == STEPS + 1
        assert any(v != blocked["rows"][0] for v in blocked["rows"][1:]) or model.startswith(("Setpoint", "PID")), \
            f"{model}: outputs never change"


@pytest.mark.parametrize("kind", ["SingleMass", "DoubleMass"])
def test_hil_adapter_client_runs_on_the_standard_library_alone(unzipped_fmus, tmp_path: Path, kind: str) -> None:
    plant = "single-mass" if kind == "SingleMass" else "double-mass"
    runs = []
    for blocked in (True, False):  # a fresh lockstep rig for each run: the same trajectory
        with RigServer(VirtualRig(RigConfig(plant=plant, pendulum_limit=None, cart_limit=None)), "127.0.0.1", 0) as srv:
            spec = {"steps": STEPS, "params": {"card_uri": f"q4:{srv.uri}"}}
            runs.append(drive(unzipped_fmus[f"IP02HIL{kind}"], spec, blocked, tmp_path))
    blocked, normal = runs
    assert "error" not in blocked, blocked
    assert blocked["blocked_attempts"] == [] and blocked["blocked_loaded"] == []
    assert blocked["rows"] == normal["rows"]
    assert any(abs(v) > 0 for v in blocked["rows"][-1][:2])  # the rig moved


def test_changed_design_parameter_without_the_design_stack_is_one_clear_line(unzipped_fmus, tmp_path: Path) -> None:
    folder = unzipped_fmus["LQRSingleMass"]
    blocked = drive(folder, {"steps": 2, "params": {"Q_cart_position": 100.0}}, True, tmp_path)
    error = blocked["error"]
    assert "\n" not in error
    assert "parameter Q_cart_position" in error and "numpy" in error and "set the gains K_*" in error
    # the same parameter with the design stack present redesigns
    normal = drive(folder, {"steps": 2, "params": {"Q_cart_position": 100.0}, "watch": LQR_GAINS}, False, tmp_path)
    assert "error" not in normal
    shipped = drive(folder, {"steps": 2, "watch": LQR_GAINS}, False, tmp_path)
    k = normal["names"].index("K_cart_position")
    assert normal["rows"][0][k] != shipped["rows"][0][k]


def test_gains_set_directly_need_no_design_stack(unzipped_fmus, tmp_path: Path) -> None:
    """A changed sample period with the gains given: the zero-order-hold model is recomputed in plain Python."""
    folder = unzipped_fmus["LQRSingleMass"]
    shipped = drive(folder, {"steps": 0, "watch": LQR_GAINS}, False, tmp_path)
    gains = {n: v * 1.01 for n, v in zip(shipped["names"], shipped["rows"][0]) if n.startswith(("K_", "M_"))}
    spec = {"steps": 8, "step_size": 0.002, "params": {"sample_period": 0.002, **gains}, "watch": LQR_GAINS}
    blocked = drive(folder, spec, True, tmp_path)
    assert "error" not in blocked, blocked
    assert blocked["blocked_attempts"] == []
    got = dict(zip(blocked["names"], blocked["rows"][0]))
    assert all(got[n] == v for n, v in gains.items())
    conflict = drive(folder, {"steps": 1, "params": {"R": 0.5, **gains}}, True, tmp_path)
    assert "parameters R and K_" in conflict["error"]


def test_cli_run_imports_no_analysis_stack(project_fmu_dir, tmp_path: Path) -> None:
    """``ipcosim run`` without --plot loads neither the plotting, design nor cluster stacks (cold-start cost)."""
    fmu_dir = project_fmu_dir
    code = ("import sys\nfrom ipcosim.harness.cli import main\n"
            f"rc = main(['run', 'single-mass-lqr', '--stop-time', '0.05', '--quiet', '--fmu-dir', {str(fmu_dir)!r}, "
            f"'--out', {str(tmp_path / 'out')!r}])\n"
            "print(rc, sorted({m.split('.')[0] for m in sys.modules} & {'matplotlib', 'scipy', 'control', 'dask', "
            "'distributed', 'pandas'}))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == "0 []"
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert metrics["wall_time_s"] > 0 and metrics["loop_real_time_factor"] > metrics["real_time_factor"] > 0


def test_redesign_after_the_first_extraction_is_gone(project_fmu_dir, tmp_path: Path) -> None:
    """One FMU build loaded from two extraction folders shares one private package; when the first
    folder is deleted, the second instance's lazily imported design modules come from its own folder."""
    import shutil

    from fmi_helpers import instantiate

    fmu = project_fmu_dir / "LQRDoubleMass.fmu"
    first = instantiate(fmu, tmp_path / "first")
    first.slave.setupExperiment(startTime=0.0)
    first.slave.enterInitializationMode()
    first.slave.exitInitializationMode()  # the shipped gains: no design module imported
    first.slave.terminate()
    first.slave.freeInstance()
    shutil.rmtree(tmp_path / "first")
    second = instantiate(fmu, tmp_path / "second")
    second.slave.setupExperiment(startTime=0.0)
    second.slave.enterInitializationMode()
    second.set(sample_period=0.002)
    second.slave.exitInitializationMode()  # redesign: imports the private design module now
    assert second.get("K_pendulum_angle")[0] != 0.0, second.text()
    second.slave.terminate()
    second.slave.freeInstance()


def test_build_in_a_process_that_loaded_the_same_build_from_a_deleted_folder(project_fmu_dir, tmp_path: Path) -> None:
    """The build imports its staged sources, not the copy of the same private package an FMU loaded
    earlier in this process from a folder that is gone."""
    import shutil

    from fmi_helpers import instantiate

    from ipcosim.fmus.pybuild import build_all

    fmu = project_fmu_dir / "LQRSingleMass.fmu"
    loaded = instantiate(fmu, tmp_path / "loaded")
    loaded.slave.setupExperiment(startTime=0.0)
    loaded.slave.enterInitializationMode()
    loaded.slave.exitInitializationMode()
    loaded.slave.terminate()
    loaded.slave.freeInstance()
    shutil.rmtree(tmp_path / "loaded")
    (result,) = build_all(tmp_path / "rebuilt", scripts=[ROOT / "controllers" / "fmu_lqr_single_mass.py"])
    assert result.built and result.fmu.name == fmu.name
    assert zipfile.ZipFile(result.fmu).namelist() == zipfile.ZipFile(fmu).namelist()
