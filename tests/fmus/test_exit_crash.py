"""No host crashes at exit, and a host that is not Python runs the FMUs to fmpy's answer.

Each test starts fresh host processes (two at a time) that load the Setpoint, the LQR
controller and the plant FMU for both plant kinds, run the closed loops and exit:

* 50 fmpy processes and 50 processes of a minimal FMI host written in C (``hosts/fmi_host.c``,
  compiled here with the system compiler): every one must exit 0. Half of them free every
  instance and close the binaries first, half exit with everything loaded. Before the
  wrapper fix (``ipcosim.fmus.wrapper``) about 1 in 5 fmpy and 1 in 3 C-host exits aborted.
* The C host's 10 s run at 1 ms against fmpy's (``hosts/fmpy_host.py``, same calls in the
  same order): final cart positions equal to 1e-9.
* fmpy freeing and unloading one FMU binary over and over while another stays loaded.

The C host is what ``docs/other-tools.md`` tells users of other tools: libpython preloaded,
``PYTHONHOME`` set; see :func:`c_host_env`.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
HOSTS = Path(__file__).resolve().parents[1] / "hosts"
MODELS = {"Setpoint": "controllers/fmu_setpoint.py", "LQRSingleMass": "controllers/fmu_lqr_single_mass.py",
          "LQRDoubleMass": "controllers/fmu_lqr_double_mass.py", "IP02SingleMass": "fmus/fmu_ip02_single_mass.py",
          "IP02DoubleMass": "fmus/fmu_ip02_double_mass.py"}
#: (controller, plant, the plant's measured outputs = the controller's inputs after ``reference``)
LOOPS = (("LQRSingleMass", "IP02SingleMass", ("cart_position", "pendulum_angle")),
         ("LQRDoubleMass", "IP02DoubleMass", ("active_cart_position", "passive_cart_position", "pendulum_angle")))
RUNS = 50
WORKERS = max(1, min(2, os.cpu_count() or 1))

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def loop_args(tmp_path_factory: pytest.TempPathFactory, project_fmus: dict[str, Path]) -> list[str]:
    """The FMU arguments of both loops (``DIR:MODEL_IDENTIFIER:GUID:IN_VRS:OUT_VRS``), FMUs of this run's build
    unzipped once."""
    from fmpy import extract, read_model_description

    out = tmp_path_factory.mktemp("exit-fmus")
    built = {model: project_fmus[script] for model, script in MODELS.items()}

    def spec(model: str, inputs: tuple[str, ...], outputs: tuple[str, ...]) -> str:
        md = read_model_description(str(built[model]))
        vr = {v.name: v.valueReference for v in md.modelVariables}
        unzip = out / model
        if not unzip.exists():
            extract(str(built[model]), unzipdir=str(unzip))
        return ":".join([str(unzip), md.coSimulation.modelIdentifier, md.guid,
                         ",".join(str(vr[n]) for n in inputs), ",".join(str(vr[n]) for n in outputs)])

    args: list[str] = []
    for controller, plant, measured in LOOPS:
        args += [spec("Setpoint", (), ("reference",)), spec(controller, ("reference", *measured), ("voltage",)),
                 spec(plant, ("voltage",), measured)]
    return args


def libpython() -> Path | None:
    """The shared libpython of the running interpreter (the one the FMUs are built against), if it has one."""
    if not sysconfig.get_config_var("Py_ENABLE_SHARED"):
        return None
    path = Path(sysconfig.get_config_var("LIBDIR"), sysconfig.get_config_var("INSTSONAME"))
    return path if path.is_file() else None


def c_host_env(lib: Path) -> dict[str, str]:
    """What a user of a non-Python FMI host sets (docs/other-tools.md): libpython preloaded, PYTHONHOME.

    No ``PYTHONPATH``: with their shipped parameters the FMUs run on the standard library of
    the base interpreter alone (no virtual environment, no numpy), which this proves.
    """
    env = dict(os.environ, LD_PRELOAD=str(lib), PYTHONHOME=sys.base_prefix)
    for name in ("PYTHONSTARTUP", "PYTHONPATH", "VIRTUAL_ENV"):
        env.pop(name, None)
    return env


@pytest.fixture(scope="module")
def c_host(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``hosts/fmi_host.c`` compiled with the system compiler against fmpy's FMI 2.0 headers."""
    import fmpy

    compiler = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
    if not compiler:
        pytest.skip("no C compiler (cc, gcc or clang on PATH, or $CC): the C FMI host cannot be built")
    headers = Path(fmpy.__file__).parent / "c-code"
    if not (headers / "fmi2FunctionTypes.h").is_file():
        pytest.skip(f"fmpy's FMI 2.0 headers are missing ({headers})")
    if libpython() is None:
        pytest.skip("this Python has no shared libpython: a non-Python host cannot load pythonfmu FMUs with it")
    exe = tmp_path_factory.mktemp("c-host") / "fmi_host"
    cmd = [compiler, "-std=c11", "-D_GNU_SOURCE", "-O2", "-Wall", "-Wextra", "-Werror", f"-I{headers}",
           "-o", str(exe), str(HOSTS / "fmi_host.c"), "-ldl"]
    result = subprocess.run(cmd, capture_output=True, text=True)
    assert result.returncode == 0, f"compiling the C host failed:\n{' '.join(cmd)}\n{result.stderr}"
    return exe


def _run_all(commands: list[tuple[list[str], dict[str, str] | None]]) -> list[subprocess.CompletedProcess]:
    def run(item: tuple[list[str], dict[str, str] | None]) -> subprocess.CompletedProcess:
        cmd, env = item
        return subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)

    with ThreadPoolExecutor(max_workers=WORKERS) as pool:
        return list(pool.map(run, commands))


def _final_outputs(stdout: str) -> list[list[float]]:
    rows = [line.split(":", 1)[1].split() for line in stdout.splitlines() if line.startswith("loop ")]
    return [[float(v) for v in row] for row in rows]


def _assert_all_exit_cleanly(results: list[subprocess.CompletedProcess], host: str) -> None:
    failed = [(k, r.returncode, r.stderr.strip().splitlines()[-1:] if r.stderr.strip() else [])
              for k, r in enumerate(results) if r.returncode != 0]
    assert not failed, f"{host}: {len(failed)} of {len(results)} processes did not exit 0 (run, code, last line): " \
                       f"{failed}"
    for k, r in enumerate(results):
        assert len(_final_outputs(r.stdout)) == len(LOOPS), f"{host} run {k} printed no result: {r.stdout!r}"


def _commands(host: list[str], loop_args: list[str], stop: str, env: dict[str, str] | None):
    return [(host + (["--keep"] if k % 2 else []) + [stop, "0.001"] + loop_args, env) for k in range(RUNS)]


@pytest.mark.slow
def test_fifty_fmpy_processes_exit_cleanly(loop_args: list[str]) -> None:
    results = _run_all(_commands([sys.executable, str(HOSTS / "fmpy_host.py")], loop_args, "0.05", None))
    _assert_all_exit_cleanly(results, "fmpy host")


@pytest.mark.slow
def test_fifty_c_host_processes_exit_cleanly(c_host: Path, loop_args: list[str]) -> None:
    results = _run_all(_commands([str(c_host)], loop_args, "0.05", c_host_env(libpython())))
    _assert_all_exit_cleanly(results, "C host")


@pytest.mark.slow
def test_c_host_matches_fmpy(c_host: Path, loop_args: list[str]) -> None:
    c_run, py_run = _run_all([([str(c_host), "10", "0.001"] + loop_args, c_host_env(libpython())),
                              ([sys.executable, str(HOSTS / "fmpy_host.py"), "10", "0.001"] + loop_args, None)])
    for run, host in ((c_run, "C host"), (py_run, "fmpy host")):
        assert run.returncode == 0, f"{host} exited {run.returncode}: {run.stderr[-2000:]}"
    c_out, py_out = _final_outputs(c_run.stdout), _final_outputs(py_run.stdout)
    assert len(c_out) == len(py_out) == len(LOOPS)
    for (_, plant, measured), c_row, py_row in zip(LOOPS, c_out, py_out):
        for name, c_value, py_value in zip(measured, c_row, py_row):
            if name.endswith("cart_position"):
                assert c_value == pytest.approx(py_value, abs=1e-9, rel=0), \
                    f"{plant}.{name}: C host {c_value} m, fmpy {py_value} m"
        # the motor-driven cart reached the task's 0.05 m: both hosts really closed the loop
        assert c_row[0] == pytest.approx(0.05, abs=1e-3), f"{plant}: final cart position {c_row[0]} m"


def test_fmpy_unloads_and_reloads_one_fmu_while_another_stays(loop_args: list[str]) -> None:
    setpoint, plant = (":".join(a.split(":")[:3]) for a in (loop_args[0], loop_args[2]))
    cycles = 5
    result = subprocess.run([sys.executable, str(HOSTS / "fmpy_unload_cycle.py"), plant, setpoint, str(cycles)],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, f"exit {result.returncode}: {result.stderr[-2000:]}"
    lines = result.stdout.splitlines()
    # the cycled binary really left the process each time (the kept one was loaded first)
    assert [f"unloaded {k}" for k in range(cycles)] == [line for line in lines if line.startswith("unloaded")]
    assert lines[-1] == f"kept stepped {cycles * 10 + 1}"


def test_c_host_without_libpython_fails_in_one_line(c_host: Path, loop_args: list[str]) -> None:
    env = {k: v for k, v in c_host_env(libpython()).items() if k != "LD_PRELOAD"}
    result = subprocess.run([str(c_host), "0.01", "0.001"] + loop_args[:3], env=env, capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Setpoint: dlopen failed" in lines[0] and "undefined symbol: _Py" in lines[0], lines
