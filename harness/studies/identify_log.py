"""The log an identification reads: a run folder's ``results.csv`` or a CSV file, its voltage and measured
positions (:func:`read_log`), refused in one line when it cannot give what is asked (:class:`IdentifyError`):
a missing column, too few rows, uneven time, an excitation that does not run through the log, a start that
is not hanging (:mod:`ipcosim.harness.studies.identify`).
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ipcosim.errors import UsageError
from ipcosim.fmus.params import KINDS
from ipcosim.fmus.physics import MEASURED

#: The excitation must run through the whole log: each tenth of it holds at least this share of the log's voltage
#: RMS (a step response spends its voltage in its first second; the identify experiments' multisine 0.84 to 1.24).
EXCITED_SHARE = 0.25
VOLTAGE_COLUMNS = ("plant.voltage", "controller.voltage")
#: How far from hanging (pi, or 0 on an encoder zeroed there) the log's first angle may be [rad].
HANGING_TOLERANCE = 0.05


class IdentifyError(UsageError):
    """A log that cannot give what was asked (missing columns, a parameter the excitation did not move)."""


@dataclass(frozen=True)
class Log:
    """The columns of a run's log that identification uses."""

    display: str
    time: np.ndarray
    voltage: np.ndarray
    y: np.ndarray                  # rows x measured outputs
    outputs: tuple[str, ...]

    @property
    def step(self) -> float:
        """The log's sample interval [s]."""
        return float(self.time[1] - self.time[0])


def read_log(source: Path, kind: str) -> Log:
    """The voltage and measured positions of a run folder's ``results.csv`` or of a CSV file.

    Raises
    ------
    IdentifyError
        A missing file or column, too few rows, or a time column that is not evenly spaced.
    """
    path = source / "results.csv" if source.is_dir() else source
    if not path.is_file():
        raise IdentifyError(f"{path}: no such file (give a run folder holding results.csv, or a CSV file)")
    with path.open(newline="") as fh:
        header = next(csv.reader(fh), [])
    wanted = [f"plant.{n}" for n in MEASURED[kind]]
    voltage = next((c for c in VOLTAGE_COLUMNS if c in header), None)
    missing = [c for c in ("time", *wanted) if c not in header] + ([] if voltage else ["plant.voltage"])
    if missing:
        other = [k for k in KINDS if k != kind and all(f"plant.{n}" in header for n in MEASURED[k])]
        if other and voltage:
            raise IdentifyError(f"{path}: the log is a {other[0]} plant's (columns "
                                f"{', '.join(f'plant.{n}' for n in MEASURED[other[0]])}), not a {kind}'s: give "
                                f"--plant {other[0]}")
        raise IdentifyError(f"{path}: no column {missing[0]} (a {kind} log needs time, plant.voltage and "
                            f"{', '.join(wanted)})")
    data = np.loadtxt(path, delimiter=",", skiprows=1, usecols=[header.index(c) for c in ("time", voltage, *wanted)],
                      ndmin=2)
    if len(data) < 1000:
        raise IdentifyError(f"{path}: {len(data)} rows; identification needs at least 1000 samples")
    dt = np.diff(data[:, 0])
    if not np.all(np.isfinite(data)) or np.ptp(dt) > 1e-6 * dt[0] or dt[0] <= 0:
        raise IdentifyError(f"{path}: the time column is not evenly spaced (or a value is not finite)")
    y = data[:, 2:].copy()
    y[:, -1] += _hanging_offset(float(y[0, -1]), path)
    _check_excitation(data[:, 0], data[:, 1], path)
    return Log(str(path), data[:, 0], data[:, 1], y, tuple(MEASURED[kind]))


def _check_excitation(time: np.ndarray, voltage: np.ndarray, path: Path) -> None:
    """Refuse a log whose voltage does not excite the plant through the whole log (``EXCITED_SHARE``): a closed-loop
    step response, whose voltage dies out after its first second, says nothing of the parameters in the rest of the
    fit or in the held-out quarter, and its fit would be confidently wrong."""
    rms = float(np.sqrt(np.mean(voltage ** 2)))
    parts = np.array_split(np.arange(len(voltage)), 10)
    shares = [float(np.sqrt(np.mean(voltage[i] ** 2))) / rms if rms > 0 else 0.0 for i in parts]
    k = int(np.argmin(shares))
    if shares[k] < EXCITED_SHARE:
        start, end = time[parts[k][0]], time[parts[k][-1]]
        raise IdentifyError(f"{path}: the voltage does not excite the plant through the log (from {start:.3g} s to "
                            f"{end:.3g} s its RMS is {shares[k]:.0%} of the log's): identification needs an "
                            "excitation experiment's log (ipcosim run KIND-identify), not a step response")


def _hanging_offset(angle0: float, path: Path) -> float:
    """What to add to the logged angle so that the experiment's start (at rest, hanging) reads pi: 0 for
    a plant FMU's absolute angle, pi for a rig whose encoder was zeroed at the start (``IP02HIL*``)."""
    for offset in (0.0, math.pi, -math.pi):
        if abs(angle0 + offset - math.pi) < HANGING_TOLERANCE:
            return offset
    raise IdentifyError(f"{path}: the pendulum angle starts at {angle0:.4g} rad, neither hanging (pi) nor zeroed "
                        "there (0): identification needs the identify experiment's start, at rest and hanging")
