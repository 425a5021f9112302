"""``make crosscheck``: the FMUs with reference results in the FMI cross-check layout, validated by fmpy.

Layout (the FMI community's ``fmi-cross-check`` repository)::

    OUT/fmus/2.0/cs/linux64/<tool>/<version>/<Model>/
        <Model>.fmu  <Model>_ref.csv  <Model>_in.csv (models with inputs)  <Model>_ref.opt  README.md

with ``<tool>`` = ``ipcosim-python`` and ``ipcosim-native``. Each FMU runs alone in fmpy on
a fixed input signal (``_in.csv``: a voltage pulse for the plants; a reference step and slowly
moving measured positions for the controllers); ``_ref.csv`` holds its outputs. The tree is
then checked with ``fmpy.cross_check.validate_vendor_repo.validate_repo``.

    python -m evidence.fmi_crosscheck [OUT] [--python DIR] [--native DIR]
"""
from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

import numpy as np

from ipcosim.errors import IpcosimError

STOP_TIME = 2.0
STEP = 1e-3


class CrossCheckLayoutError(IpcosimError, RuntimeError):
    """The cross-check tree has problems (listed)."""


def _input_signal(names: list[str]) -> np.ndarray | None:
    """A fixed input signal for the inputs ``names`` (structured array with ``time``), or None."""
    if not names:
        return None
    t = np.round(np.arange(0.0, STOP_TIME + STEP / 2, STEP), 9)
    data = np.zeros(len(t), dtype=[("time", "f8")] + [(n, "f8") for n in names])
    data["time"] = t
    for n in names:
        if n == "voltage":
            data[n] = np.where((t >= 0.1) & (t < 0.3), 1.0, 0.0)
        elif n == "reference":
            data[n] = np.where(t >= 0.1, 0.05, 0.0)
        elif n == "pendulum_angle":
            data[n] = 0.01 * np.sin(2.0 * t)
        else:
            data[n] = 0.04 * (1.0 - np.exp(-t))
    return data


def _write_csv(path: Path, data: np.ndarray) -> None:
    names = data.dtype.names
    assert names is not None
    rows = [",".join(f'"{n}"' if n != "time" else "time" for n in names)]
    rows += [",".join(repr(float(x)) for x in row) for row in data]
    path.write_text("\n".join(rows) + "\n")


def write_model(fmu: Path, dest: Path, tool: str) -> None:
    """One model folder: the FMU, its input, reference result, options and README."""
    from fmpy import read_model_description, simulate_fmu

    md = read_model_description(str(fmu))
    inputs = [v.name for v in md.modelVariables if v.causality == "input"]
    outputs = [v.name for v in md.modelVariables if v.causality == "output"]
    dest.mkdir(parents=True, exist_ok=True)
    shutil.copy(fmu, dest / fmu.name)
    signal = _input_signal(inputs)
    if signal is not None:
        _write_csv(dest / f"{fmu.stem}_in.csv", signal)
    result = simulate_fmu(str(fmu), stop_time=STOP_TIME, step_size=STEP, output_interval=STEP, input=signal,
                          output=outputs)
    _write_csv(dest / f"{fmu.stem}_ref.csv", result)
    (dest / f"{fmu.stem}_ref.opt").write_text(f"StartTime, 0.0\nStopTime, {STOP_TIME}\nStepSize, {STEP}\n"
                                              "RelTol, 1e-06\n")
    (dest / "README.md").write_text(f"# {fmu.stem} ({tool})\n\n{md.description or ''}\n\nReference result: fmpy "
                                    f"co-simulation, step {STEP} s, 0..{STOP_TIME} s, inputs from "
                                    f"`{fmu.stem}_in.csv` where the model has inputs.\n")


def write_tree(out: Path, flavours: dict[str, Path], version: str) -> tuple[int, list[str]]:
    """Write every FMU of each ``{tool: folder}`` into ``out``; return (models fmpy found, its problems)."""
    from fmpy.cross_check.validate_vendor_repo import validate_repo

    for tool, folder in flavours.items():
        fmus = sorted(Path(folder).glob("*.fmu"))
        if not fmus:
            raise CrossCheckLayoutError(f"no FMUs in {folder} (run `ipcosim build --native`)")
        for fmu in fmus:
            if "HIL" in fmu.stem:
                continue  # the HIL adapter needs a rig
            write_model(fmu, out / "fmus" / "2.0" / "cs" / "linux64" / tool / version / fmu.stem, tool)
    fmu_count, _, problems = validate_repo(str(out))
    return fmu_count, list(problems)


def main(argv: list[str] | None = None) -> int:
    """Command line (see the module docstring)."""
    from ipcosim.harness.support.paths import BUILD_DIR

    p = argparse.ArgumentParser(prog="python -m evidence.fmi_crosscheck", allow_abbrev=False)
    p.add_argument("out", nargs="?", default=str(Path(BUILD_DIR) / "crosscheck"))
    p.add_argument("--python", default=str(Path(BUILD_DIR) / "fmus"))
    p.add_argument("--native", default=str(Path(BUILD_DIR) / "fmus-native"))
    args = p.parse_args(argv)
    out = Path(args.out)
    if out.exists():
        shutil.rmtree(out)
    try:
        from importlib import metadata
        version = metadata.version("ipcosim")
    except Exception:  # noqa: BLE001 -- an uninstalled checkout
        version = "dev"
    try:
        flavours = {"ipcosim-python": Path(args.python), "ipcosim-native": Path(args.native)}
        count, problems = write_tree(out, flavours, version)
    except CrossCheckLayoutError as exc:
        print(f"crosscheck: error: {exc}", file=sys.stderr)
        return 1
    for problem in problems:
        print(f"crosscheck: {problem}", file=sys.stderr)
    print(f"crosscheck: {count} models in {out} validated by fmpy.cross_check: {len(problems)} problems")
    return 1 if problems or count == 0 else 0


if __name__ == "__main__":
    sys.exit(main())
