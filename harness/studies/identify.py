"""Identification: the plant's physical parameters from a run's log, with 95 % intervals.

The estimator is an output-error fit. It replays the logged voltage through the project's own plant
model (:func:`ipcosim.fmus.plant.replay`: the same ``Plant`` the plant FMUs and the virtual rig
step, on the lab bench's input path, ``ipcosim.fmus.instruments.REALISM["lab"]``; run in C by
:mod:`ipcosim.harness.native.replay` where a compiler is found, :func:`simulator`), compares the
simulated positions with the logged encoder readings, and minimizes the sum of squared
differences (each output scaled by its spread in the log): scipy's trust-region least squares
approaches the optimum, a final pass of small-step Gauss-Newton steps (:func:`_polish`) finishes it
where the stick-slip friction makes the cost rough, restarted from nearby points where it stops with a
reading a count or more off (:func:`_unstick`). Only the parameters named in ``fit`` move; every
other constant (motor, gearbox, pendulum mass and length) stays at the preset's value. The bench's
computation delay is chosen too, as the whole number of samples (``DELAY_SAMPLES``) whose trust-region
fit leaves the smaller cost: a plant FMU on the lab bench delays the logged voltage by one sample, the
lockstep rig behind the HIL adapter by none.

Held-out check: the first ``1 - HELD_OUT`` of the log is fitted; the rest is simulated on from the
start with the estimate and reported as NRMSE per output (``1 - ||y - y_sim|| / ||y - mean y||``).

Intervals (:func:`_half_widths`): the wider of two. The sandwich: the Gauss-Newton linearization
``theta - theta* ~ H^-1 J' r`` with ``H = J'J`` gives the covariance ``H^-1 S H^-1``, ``S`` the
Bartlett-weighted sum of the scores' autocovariances up to ``HAC_LAG`` samples (Newey-West: a cart that
sticks holds the same count error for many samples), ``J`` by central differences over
``COVARIANCE_STEP``; +- 1.96 standard errors. It sees the measurement's errors but not where in the
stick-slip roughness the fit stopped, which on the lab bench is the larger error. The refits
(:func:`_bootstrap`, ``refits`` of them): synthetic logs of the estimate, read by encoders with a random
sub-count zero offset, fitted as the log was but without the restarts; +- ``t(0.975, refits)`` times the
refits' root-mean-square deviation from the estimate. They see both. Neither says anything of a model that is wrong (the
held-out NRMSE is the check for that; docs/identify.md). Coulomb forces' intervals are clipped at 0.
"""
from __future__ import annotations

import csv
import math
import time as _time
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from ipcosim.errors import UsageError, closest
from ipcosim.fmus.instruments import Instruments, quantize, realism
from ipcosim.fmus.kinds import ByKind
from ipcosim.fmus.params import DEFAULT_PRESET, KINDS, PLANT_KINDS, PRESETS, preset
from ipcosim.fmus.physics import MEASURED, state_names
from ipcosim.fmus.plant import replay

#: What the excitation makes identifiable, per plant kind (the default of ``fit``; docs/identify.md, "Parameters"):
#: the carts' masses, dampings and Coulomb forces, the pivot's damping and the motor's torque constant ``Kt``, which
#: stands for the force per volt ``amplifier_gain N Kt / (rg Ra)`` (Kt and Ra are not separable at all: they enter
#: as Kt / Ra and as the armature's time constant La / Ra, 0.07 ms; the amplifier gain and Kb only through that
#: time constant, so they are options).
DEFAULT_FIT = ByKind(lambda k: k.identified)
#: The motor and amplifier constants that enter the motion (about) only through the force per volt; a fit of one of
#: them with the others at the preset makes it carry the others' errors (``Identification.parameters[...]["note"]``).
FORCE_PER_VOLT = ("Kt", "Ra", "amplifier_gain")
#: A fit is not valid when some reading of the fitted part lies farther than this from its simulation [encoder
#: counts]: the true model explains every reading to within half a count, a finished fit of it leaves at most 1.11
#: (docs/identify.md, Figures: 40 seeded fits) and 1.50 with a hidden motor error the default fit carries (Under
#: model error: 14 valid fits); a model that lacks what moved the plant (a constant off that is not fitted) leaves
#: its error in the readings: 141 to 176 counts for 10 % of Lp, 14 for 10 % of Kt held at the preset.
INVALID_COUNTS = 3.0
#: The excitation must run through the whole log: each tenth of it holds at least this share of the log's voltage
#: RMS (a step response spends its voltage in its first second; the identify experiments' multisine 0.84 to 1.24).
EXCITED_SHARE = 0.25
#: Parameters whose nominal may be 0: their fit scale [their unit] and start value.
ZERO_NOMINAL = {"b": (0.1, 0.05), "b1": (0.1, 0.05), "b2": (0.1, 0.05), "Bc": (0.01, 0.005)}
#: Parameters that can only be estimated >= 0 (the rest: > 0).
NONNEGATIVE = ("b", "b1", "b2", "Bc", "Beq", "Ba", "Bf", "Bp", "K")
HELD_OUT = 0.25
#: Computation delays tried, in whole samples of the log: the one with the lowest cost is kept (a plant
#: FMU on the lab bench delays the logged voltage by one sample; the lockstep rig behind the adapter does not).
DELAY_SAMPLES = (0, 1)
HAC_LAG = 1000
#: Forward-difference step of the Jacobian, relative to the (scaled) parameter. Stick-slip friction
#: makes the outputs step when a cart's stick decision flips: a step of 1e-3 measured those flips and
#: led the fit astray (a 12 s double-mass log ended 8 % off in Ma, held-out NRMSE 85 %); 1e-2 averages
#: over them (the same log: every parameter within 2 %, NRMSE 98.8 %).
FD_STEP = 1e-2
#: The final pass (:func:`_polish`): Gauss-Newton steps from central differences at these relative steps of
#: the scaled parameters, tried in order until one lowers the cost, with step lengths ``POLISH_LENGTHS``; at
#: most ``POLISH_ITERATIONS`` steps, within ``SIMULATION_BUDGET``. 1e-5 is about a tenth of a standard error: it
#: measures the slope between the stick decisions that flip, where the trust region's 1 % secant stopped; the
#: larger steps take over where a flip sits inside the small one.
POLISH_STEPS = (1e-5, 1e-4, 1e-3)
POLISH_LENGTHS = (1.0, 0.5, 0.25)
POLISH_ITERATIONS = 8
#: Trust-region evaluations of the refit with the other computation delay (from the first fit's estimate).
DELAY_NFEV = 8
#: Simulations of the log the fit may spend before its interval (the final pass ends early rather than exceed it);
#: each refit's final pass gets what the log's had. A larger budget does not help: a fit stuck in the roughness
#: stays stuck (a double-mass log given 1200: the final pass stopped at 389, still 2.5 counts off).
SIMULATION_BUDGET = 330
#: A fit is stuck when some reading of the fitted part lies farther than this from its simulation [encoder counts]:
#: the true parameters explain every reading to within half a count, and every seeded fit that ended below one count
#: had all its truths inside their intervals; above it, a stick-slip episode of the log ends a count or more away
#: from where the estimate puts it.
STUCK_COUNTS = 1.0
#: Restarts of the final pass while the fit is stuck (:func:`_unstick`): from the best point so far moved by
#: ``RESTART_SIZES`` (in turn) times a draw of the sandwich's covariance (seeded by ``RESTART_SEED``), each finished by
#: ``RESTART_ITERATIONS`` Gauss-Newton steps, the lowest cost kept; at most ``RESTARTS`` of them and
#: ``RESTART_BUDGET`` simulations of the log.
RESTARTS = 24
RESTART_SIZES = (10.0, 30.0)
RESTART_ITERATIONS = 3
RESTART_BUDGET = 600
RESTART_SEED = 0
#: Central-difference step of the Jacobian behind the interval: ten standard errors, so that the few stick
#: decisions that flip inside it add little to a slope measured over many samples (a step of 1e-5 with one flip
#: inside it made one column, and so the information on that parameter, tens of times too large).
COVARIANCE_STEP = 1e-3
#: Refits behind the interval (:func:`_bootstrap`): synthetic logs of the estimate, each read by encoders with
#: their own sub-count zero offset, each fitted as the log was (from the preset, trust region and final pass).
BOOTSTRAP_REFITS = 8
BOOTSTRAP_SEED = 0
#: Relative standard error (from the encoders' resolution alone) above which a parameter is refused.
UNIDENTIFIABLE = 0.3
#: Variance inflation (the information on a parameter alone over what is left of it after the other fitted
#: parameters, from central differences over ``COVARIANCE_STEP`` at the start) above which a parameter is refused as
#: not separable from them. On the identify experiments' 20 s logs: Kt beside Ra 1.6e8 (they enter as Kt / Ra but
#: for the armature's 0.07 ms time constant); the default fit at most 26 (single mass) and 77 (double mass); the
#: amplifier gain beside Kt 290 to 1100 and Kb beside Kt and the damping 230 to 840 (docs/identify.md, Parameters).
INFLATION = 1e4
VOLTAGE_COLUMNS = ("plant.voltage", "controller.voltage")
#: How far from hanging (pi, or 0 on an encoder zeroed there) the log's first angle may be [rad].
HANGING_TOLERANCE = 0.05


class IdentifyError(UsageError):
    """A log that cannot give what was asked (missing columns, a parameter the excitation did not move)."""


@dataclass(frozen=True)
class IdentifyOptions:
    """What ``ipcosim identify`` does (the one options object behind the command line and Python).

    Attributes
    ----------
    source : Path
        A run folder (holding ``results.csv``) or a CSV file with ``time``, the plant's voltage and
        its measured positions (``plant.<name>`` columns).
    plant : str
        ``single-mass`` or ``double-mass``.
    fit : tuple of str
        Parameters to estimate (``ipcosim.fmus.params`` names); empty: ``DEFAULT_FIT``.
    preset : str or None
        Preset of the parameters that are not fitted, and the start of the fit (default: the plant's).
    out : Path or None
        Folder for ``identified.ssv`` and ``identified.png`` (checked writable before the fit).
    refits : int
        Refits of synthetic logs behind the intervals (:func:`_bootstrap`); 0: the sandwich alone, which does
        not cover where the fit stopped (docs/identify.md).
    """

    source: Path
    plant: str
    fit: tuple[str, ...] = ()
    preset: str | None = None
    out: Path | None = None
    refits: int = BOOTSTRAP_REFITS

    @classmethod
    def create(cls, source: Any, *, plant: str, fit: Sequence[str] | str | None = None, preset: str | None = None,
               out: Any = None, refits: int | None = None) -> "IdentifyOptions":
        """Checked options (``fit`` as names or one comma-separated string; ``refits`` None: ``BOOTSTRAP_REFITS``).

        Raises
        ------
        UsageError
            An unknown plant kind, preset or parameter name (with the closest known ones), ``refits``
            neither 0 nor a whole number >= 2, or an ``out`` that is a file or cannot be written.
        """
        refits = BOOTSTRAP_REFITS if refits is None else refits
        if isinstance(refits, bool) or not isinstance(refits, int) or refits == 1 or refits < 0:
            raise UsageError(f"--refits {refits}: give 0 (the sandwich interval alone) or a whole number >= 2")
        if plant not in KINDS:
            raise UsageError(f"--plant {plant}: expected one of {', '.join(KINDS)}")
        if preset is not None and (preset not in PRESETS or PRESETS[preset][0] != plant):
            known = [p for p, (k, _, _) in PRESETS.items() if k == plant]
            raise UsageError(f"--preset {preset}: not a {plant} preset; {closest(preset, known)}")
        names = [n.strip() for item in ([fit] if isinstance(fit, str) else (fit or ()))
                 for n in str(item).split(",") if n.strip()]
        known = [f.name for f in fields(PLANT_KINDS[plant])]
        for name in names:
            if name not in known:
                raise UsageError(f"--fit {name}: the {plant} plant has no parameter {name!r}; {closest(name, known)}")
        if out is not None:
            _check_out(Path(out))
        return cls(source=Path(source), plant=plant, fit=tuple(dict.fromkeys(names)) or DEFAULT_FIT[plant],
                   preset=preset, out=Path(out) if out is not None else None, refits=refits)


def _check_out(out: Path) -> None:
    """Refuse an ``--out`` that is not a folder, or whose nearest existing folder cannot be written (tried with a
    temporary file, removed at once)."""
    import tempfile

    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out}: not a folder (a file of that name exists)")
    existing = next(p for p in (out, *out.parents) if p.exists())
    try:
        if not existing.is_dir():
            raise NotADirectoryError(existing)
        with tempfile.TemporaryFile(dir=existing):
            pass
    except OSError as exc:
        raise UsageError(f"--out {out}: cannot write there ({existing} is not a writable folder: "
                         f"{exc.strerror or 'a file'})") from None


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


@dataclass
class Identification:
    """Estimates, intervals and fit quality of one identification (``to_json``: ``--json``, docs/identify.md)."""

    plant: str
    preset: str
    parameters: dict[str, dict[str, Any]]
    nrmse: dict[str, float]
    held_out_from_s: float
    fit_time_s: float
    simulations: int                # replays of the log the fit spent
    source: str
    values: dict[str, float] = field(default_factory=dict)   # every plant parameter of the identified model
    outputs: tuple[str, ...] = ()
    time: np.ndarray | None = field(default=None, repr=False)
    measured: np.ndarray | None = field(default=None, repr=False)
    simulated: np.ndarray | None = field(default=None, repr=False)
    input_delay_s: float = 0.0
    written: list[Path] = field(default_factory=list)   # the files ``options.out`` received
    fit_cpu_s: float = 0.0                                # CPU time of the fit (``fit_time_s``: wall)
    #: per output, the largest |simulated - measured| over the fitted part in encoder counts (<= 0.5: the
    #: estimate explains every reading to within the encoder's rounding, as the true parameters do)
    largest_residual_counts: dict[str, float] = field(default_factory=dict)
    #: how the log was simulated: ``native`` (:mod:`ipcosim.harness.native.replay`) or ``python (<why not>)``
    replay: str = "native"
    refits: int = 0                 # synthetic refits behind the intervals (:func:`_bootstrap`)
    #: per output, the encoder's resolution [m or rad per count] (the unit of ``largest_residual_counts``)
    resolutions: dict[str, float] = field(default_factory=dict)

    @property
    def valid(self) -> bool:
        """Whether the fit explains the log to within ``INVALID_COUNTS`` encoder counts: otherwise the model lacks
        something that moved the plant, and the intervals (which assume the model) claim nothing."""
        return max(self.largest_residual_counts.values(), default=0.0) <= INVALID_COUNTS

    @property
    def invalid_reason(self) -> str | None:
        """One line on why the fit is not valid (None when it is)."""
        if self.valid:
            return None
        name, counts = max(self.largest_residual_counts.items(), key=lambda kv: kv[1])
        return (f"the fit is not valid: {name} is {counts:.1f} encoder counts from its simulation (a fit of the right "
                f"model leaves at most {INVALID_COUNTS:g}): the model lacks something that moved the plant (fit more "
                "parameters, e.g. --fit with Lp, Mp or the motor constants); the intervals claim nothing")

    @property
    def fit(self) -> dict[str, float]:
        """Per output, the held-out fit ``1 - NRMSE`` (1 = perfect, 0 = no better than the mean)."""
        return {k: 1.0 - v for k, v in self.nrmse.items()}

    def to_json(self) -> dict[str, Any]:
        """``{"parameters": {NAME: {"value", "ci95", "unit", "valid"}}, "nrmse": {OUTPUT: fraction}, "fit": {OUTPUT:
        1 - nrmse}, "valid": bool, ...}``."""
        parameters = {n: {**p, "valid": self.valid} for n, p in self.parameters.items()}
        return {"parameters": parameters, "nrmse": self.nrmse, "fit": self.fit, "valid": self.valid,
                "invalid_reason": self.invalid_reason, "plant": self.plant, "preset": self.preset,
                "input_delay_s": self.input_delay_s,
                "held_out_from_s": self.held_out_from_s, "fit_time_s": self.fit_time_s, "fit_cpu_s": self.fit_cpu_s,
                "simulations": self.simulations, "largest_residual_counts": self.largest_residual_counts,
                "replay": self.replay, "refits": self.refits, "source": self.source}


class _Problem:
    """The output-error problem of one log: parameters scaled to ~1, residuals scaled per output."""

    def __init__(self, log: Log, kind: str, fit: Sequence[str], base: Any, instruments: Instruments,
                 simulator: Callable[..., Any] = replay) -> None:
        self.log, self.kind, self.fit, self.base = log, kind, tuple(fit), base
        self.instruments = instruments
        self.simulator = simulator    # ``ipcosim.fmus.plant.replay`` or its native twin (:func:`simulator`)
        self.scale = np.array([ZERO_NOMINAL.get(n, (getattr(base, n), 0))[0] or 1.0 for n in fit])
        self.start = np.array([getattr(base, n) or ZERO_NOMINAL.get(n, (0, 1.0))[1] for n in fit]) / self.scale
        x0 = [0.0] * len(state_names(kind))
        for j, name in enumerate(MEASURED[kind]):
            x0[state_names(kind).index(name)] = float(log.y[0, j])
        self.x0 = x0
        self.n_fit = int(round(len(log.time) * (1 - HELD_OUT)))
        self.spread = np.maximum(log.y[: self.n_fit].std(axis=0), 1e-9)
        self._last: tuple[np.ndarray, np.ndarray] | None = None
        self.simulations = 0          # replays of the log so far (``Identification.simulations``)

    def params(self, theta: np.ndarray) -> Any:
        return replace(self.base, **{n: float(t * s) for n, t, s in zip(self.fit, theta, self.scale)})

    def simulate(self, theta: np.ndarray, rows: int) -> np.ndarray:
        """Simulated positions for the first ``rows`` rows of the log."""
        return np.asarray(self.simulator(self.params(theta), self.log.voltage[: rows - 1], self.log.step, self.x0,
                                         self.instruments))

    def residuals(self, theta: np.ndarray) -> np.ndarray:
        """Scaled differences simulated - measured over the fitted part (cached for the last ``theta``)."""
        if self._last is not None and np.array_equal(self._last[0], theta):
            return self._last[1]
        r = self._residuals(theta)
        self._last = (theta.copy(), r)
        return r

    def _residuals(self, theta: np.ndarray) -> np.ndarray:
        y = self.log.y[: self.n_fit]
        self.simulations += 1
        try:
            sim = self.simulate(theta, self.n_fit)
        except (FloatingPointError, ValueError):
            return np.full(y.size, 1e3)
        return ((sim - y) / self.spread).ravel()

    def cost(self, theta: np.ndarray) -> float:
        """Half the sum of the squared scaled residuals."""
        r = self.residuals(theta)
        return 0.5 * float(r @ r)

    def central_jacobian(self, theta: np.ndarray, step: float) -> np.ndarray:
        """Central differences of the residuals at the relative ``step``, two simulations per parameter."""
        cols = []
        for i in range(len(theta)):
            d = step * max(abs(theta[i]), 1e-3)
            up, down = theta.copy(), theta.copy()
            up[i] += d
            down[i] -= d
            cols.append((self._residuals(up) - self._residuals(down)) / (2 * d))
        return np.column_stack(cols)

    def jacobian(self, theta: np.ndarray, r0: np.ndarray | None = None) -> np.ndarray:
        """Forward differences of the residuals, one simulation per parameter."""
        r0 = self.residuals(theta) if r0 is None else r0
        cols = []
        for i in range(len(theta)):
            d = FD_STEP * max(1.0, abs(theta[i]))
            t = theta.copy()
            t[i] += d
            cols.append((self._residuals(t) - r0) / d)
        return np.column_stack(cols)


def _resolutions(problem: _Problem) -> np.ndarray:
    """Each measured output's encoder resolution [m or rad] (1e-9 where the bench has none)."""
    inst = problem.instruments
    return np.maximum([inst.pendulum_resolution if n == "pendulum_angle" else inst.cart_resolution
                       for n in problem.log.outputs], 1e-9)


def _check_identifiable(problem: _Problem, J: np.ndarray) -> None:
    """Refuse a parameter whose standard error from the encoders' resolution alone exceeds ``UNIDENTIFIABLE``, or
    exceeds ``sqrt(INFLATION)`` times what it would be were the other parameters known (told apart from them only by
    an effect a hundred times smaller than its own: Kt beside Ra, through the armature's 0.07 ms time constant)."""
    sigma = np.tile(_resolutions(problem) / math.sqrt(12) / problem.spread, problem.n_fit)
    Jw = J / sigma[:, None]
    H = Jw.T @ Jw
    for i, name in enumerate(problem.fit):
        rest = [j for j in range(len(problem.fit)) if j != i]
        # the information on parameter i left after the others explain what they can (Schur complement)
        info = H[i, i] - (H[i, rest] @ np.linalg.pinv(H[np.ix_(rest, rest)]) @ H[rest, i] if rest else 0.0)
        start = problem.start[i]
        limit = UNIDENTIFIABLE * max(start, 1.0)
        if not info > 0 or 1 / math.sqrt(info) > limit or info < H[i, i] / INFLATION:
            if H[i, i] > 0 and 1 / math.sqrt(H[i, i]) <= limit:   # moved alone, but as another fitted one moves
                partner = max(rest, key=lambda j: abs(H[i, j]) / math.sqrt(H[i, i] * H[j, j]))
                raise IdentifyError(f"{problem.log.display}: cannot identify {name} apart from "
                                    f"{problem.fit[partner]}: the log moves as much when one changes as when the "
                                    "other does (fit one of them; docs/identify.md, Parameters)")
            raise IdentifyError(f"{problem.log.display}: cannot identify {name}: the excitation did not move it "
                                f"(the outputs change by less than the encoders resolve when {name} changes)")


def _covariance(J: np.ndarray, r: np.ndarray, m: int, lag: int = HAC_LAG) -> np.ndarray:
    """Newey-West covariance of the least-squares estimate (``m`` residuals per sample)."""
    p = J.shape[1]
    scores = (J * r[:, None]).reshape(-1, m, p).sum(axis=1)     # one score per sample
    n = len(scores)
    nfft = 1 << (2 * n - 1).bit_length()
    F = np.fft.rfft(scores, nfft, axis=0)
    S = np.zeros((p, p))
    for a in range(p):
        for b in range(a, p):
            c = np.fft.irfft(F[:, a] * np.conj(F[:, b]), nfft)   # c[l] = sum_t s_a[t+l] s_b[t]
            w = 1 - np.arange(lag + 1) / (lag + 1)
            v = w[0] * c[0] + np.sum(w[1:] * (c[1: lag + 1] + c[-lag:][::-1]))
            S[a, b] = S[b, a] = v
    Hinv = np.linalg.pinv(J.T @ J)
    return Hinv @ S @ Hinv


def nrmse(y: np.ndarray, y_sim: np.ndarray) -> float:
    """``||y - y_sim|| / ||y - mean(y)||`` (0 = perfect fit, 1 = no better than the mean; the fit is 1 - NRMSE)."""
    spread = np.linalg.norm(y - y.mean())
    return float(np.linalg.norm(y - y_sim) / spread) if spread > 0 else float("nan")


def simulator(kind: str) -> tuple[Callable[..., Any], str]:
    """The simulation of the log and its name: the native replay (:mod:`ipcosim.harness.native.replay`, the same
    numbers 30 to 40 times faster) where a C compiler is found, else :func:`ipcosim.fmus.plant.replay`
    (``python (<why>)``)."""
    from ipcosim.harness.native.replay import ReplayUnavailable, native_replay

    try:
        return native_replay(kind), "native"
    except ReplayUnavailable as exc:
        return replay, f"python ({exc})"


def identify(options: IdentifyOptions, started: Callable[[], None] | None = None) -> Identification:
    """Estimate ``options.fit`` from the log ``options.source`` (see the module docstring); with
    ``options.out``, write ``identified.ssv`` and ``identified.png`` there (:func:`write_identified`).
    ``started`` is called once the log and the parameters are accepted, when the fit (seconds) begins.

    Raises
    ------
    IdentifyError
        A log without the needed columns, or one whose excitation did not move a requested parameter.
    """
    kind = options.plant
    name = options.preset or DEFAULT_PRESET[kind]
    log = read_log(options.source, kind)
    bench = realism("lab", kind)[0]
    t0, c0 = _time.perf_counter(), _time.process_time()
    simulate, how = simulator(kind)
    problem = _Problem(log, kind, options.fit, preset(name), bench, simulate)
    _check_identifiable(problem, problem.central_jacobian(problem.start, COVARIANCE_STEP))
    if started is not None:
        started()
    sol = _fit(problem, problem.start)
    candidates = [problem]
    for samples in DELAY_SAMPLES:   # the computation delay: whole samples, the one that fits best
        delay = samples * log.step
        if abs(delay - problem.instruments.input_delay) > 1e-12:
            other = _Problem(log, kind, options.fit, preset(name), replace(bench, input_delay=delay), simulate)
            candidates.append(other)
            refit = _fit(other, sol.x, max_nfev=DELAY_NFEV)
            if refit.cost < sol.cost:
                problem, sol = other, refit
    spent = sum(c.simulations for c in candidates)
    best = _finish(problem, sol.x, SIMULATION_BUDGET - spent)
    result = _result(best, name, sum(c.simulations for c in candidates), options.refits)
    result.fit_time_s, result.fit_cpu_s = _time.perf_counter() - t0, _time.process_time() - c0
    result.replay, result.refits = how, options.refits
    if options.out is not None:
        result.written = write_identified(result, options.out)
    return result


def _fit(problem: _Problem, start: np.ndarray, max_nfev: int = 20) -> Any:
    """``scipy.optimize.least_squares`` of the problem's residuals from ``start`` (bounded, trust region): the
    approach to the optimum, which :func:`_polish` finishes (more of these steps would stop in the roughness)."""
    from scipy.optimize import least_squares

    return least_squares(problem.residuals, start, jac=lambda t: problem.jacobian(t), method="trf",
                         bounds=(_lower(problem), np.inf), x_scale=1.0, xtol=1e-8, ftol=1e-10, max_nfev=max_nfev)


@dataclass
class _Finished:
    """The end of :func:`_polish`: the estimate, its cost and the Jacobian there."""

    problem: _Problem
    x: np.ndarray
    cost: float
    jac: np.ndarray | None
    budget: float = math.inf      # the simulations the final pass was given (a refit gets as many)
    refit_simulations: int = 0    # what the interval's refits spent (:func:`_bootstrap`)


def _polish(problem: _Problem, start: np.ndarray, iterations: int, budget: float = math.inf) -> _Finished:
    """Finish the fit from ``start``: Gauss-Newton steps on small-step central differences, kept only when they
    lower the cost.

    The stick-slip friction makes the cost rough: each stick decision that flips as a parameter changes adds a
    small step to it, and the trust region's 1 % secant (``FD_STEP``) stops in that roughness, 10 to 100
    standard errors from the optimum. Between the flips the cost is smooth; central differences over a tenth of a
    standard error (``POLISH_STEPS``) see that slope, and a step is tried at the lengths ``POLISH_LENGTHS`` and
    taken only if it lowers the cost (no step is forced through a flip); at most ``iterations`` steps and about
    ``budget`` simulations (leaving what the sandwich's Jacobian at the end needs, :func:`_finish`).
    """
    x, cost = np.asarray(start, float), problem.cost(start)
    # a Jacobian and its line search, plus the Jacobian for the interval, must fit in what is left of the budget
    last = problem.simulations + budget - (2 * len(x) + len(POLISH_LENGTHS)) - 2 * len(x)
    for _ in range(iterations):
        for J in (problem.central_jacobian(x, step) for step in POLISH_STEPS if problem.simulations <= last):
            direction = -np.linalg.lstsq(J, problem.residuals(x), rcond=None)[0]
            trial = min((problem.cost(_bounded(problem, x + a * direction)), a) for a in POLISH_LENGTHS)
            if trial[0] < cost:
                x, cost = _bounded(problem, x + trial[1] * direction), trial[0]
                break
        else:
            break
    return _Finished(problem, x, cost, None, budget)


def _finish(problem: _Problem, start: np.ndarray, budget: float, restarts: bool = True) -> _Finished:
    """The final pass (:func:`_polish`, about ``budget`` simulations) and, with ``restarts`` where it leaves the
    fit stuck, its restarts (:func:`_unstick`, ``RESTART_BUDGET`` more); with ``restarts`` (the log's own fit)
    also the sandwich's Jacobian at the end (central differences over ``COVARIANCE_STEP``)."""
    finished = _polish(problem, start, POLISH_ITERATIONS, budget)
    if restarts:
        finished = _unstick(finished, RESTART_BUDGET)
        finished.jac = problem.central_jacobian(finished.x, COVARIANCE_STEP)
    return finished


def _unstick(finished: _Finished, budget: float) -> _Finished:
    """Restart the final pass from points near a stuck estimate (:data:`STUCK_COUNTS`), keeping the lowest cost.

    The cost is a smooth bowl plus a small positive step for each stick decision that flips away from the truth's:
    the final pass stops where every Gauss-Newton step it tries from there crosses a flip that costs more than the
    bowl saves, and more simulations from the same point do not help. From a point a few standard errors away
    (the sandwich's covariance at the stuck estimate: moved mostly along the bowl's flat directions, where the
    flips decide) the steps cross other flips; a restart is kept only where it ends lower than the best point so
    far, and the next one starts from there. Deterministic (``RESTART_SEED``); at most ``RESTARTS`` restarts and
    about ``budget`` simulations, ending early once no reading is a count off.
    """
    problem, best = finished.problem, finished
    if not _stuck(problem, best.x):
        return finished
    end = problem.simulations + budget
    jac = problem.central_jacobian(best.x, COVARIANCE_STEP)
    w, v = np.linalg.eigh(_covariance(jac, problem.residuals(best.x), len(problem.log.outputs)))
    root = v * np.sqrt(np.maximum(w, 0.0))
    rng = np.random.default_rng(RESTART_SEED)
    for k in range(RESTARTS):
        left = end - problem.simulations
        if left < 4 * len(best.x) + len(POLISH_LENGTHS) + 1:
            break
        start = _bounded(problem, best.x + RESTART_SIZES[k % len(RESTART_SIZES)] * root @ rng.standard_normal(len(w)))
        trial = _polish(problem, start, RESTART_ITERATIONS, left)
        if trial.cost < best.cost:
            best = trial
            if not _stuck(problem, best.x):
                break
    return _Finished(problem, best.x, best.cost, None, finished.budget)


def _stuck(problem: _Problem, x: np.ndarray) -> bool:
    """Whether some reading of the fitted part lies more than ``STUCK_COUNTS`` from the simulation of ``x``."""
    return bool(_largest_counts(problem, x).max() > STUCK_COUNTS)


def _largest_counts(problem: _Problem, x: np.ndarray) -> np.ndarray:
    """Per output, the largest |simulated - measured| over the fitted part of the log, in encoder counts."""
    r = problem.residuals(x).reshape(problem.n_fit, len(problem.log.outputs))
    return np.abs(r).max(axis=0) * problem.spread / _resolutions(problem)


def _bounded(problem: _Problem, x: np.ndarray) -> np.ndarray:
    """``x`` kept inside the fit's bounds (:func:`_lower`)."""
    return np.maximum(x, _lower(problem))


def _lower(problem: _Problem) -> np.ndarray:
    """The lower bounds of the scaled parameters: 0 for the ``NONNEGATIVE`` ones, 1e-3 for the rest."""
    return np.array([0.0 if n in NONNEGATIVE else 1e-3 for n in problem.fit])


def _bootstrap(finished: _Finished, sim: np.ndarray, refits: int) -> np.ndarray:
    """The estimator's own scatter at the estimate: ``refits`` estimates (scaled) from synthetic logs.

    Each synthetic log is the estimate's simulated motion ``sim`` read by the log's encoders zeroed at the start
    with a sub-count zero offset drawn uniformly (``quantize`` with its phase moved; the same logged voltage,
    the same computation delay), fitted as the log was: from the preset, the trust region, then the final pass
    with the simulations the log's had, but without its restarts (:func:`_unstick`: they would double the
    identification's time). Its estimates scatter as a fit without restarts does -- from the encoders' rounding
    and from where in the stick-slip roughness the fit stops, which no linearization at the estimate sees --
    so the interval is wide enough for a fit stopped where the final pass stops; one the restarts finished lies
    nearer the truth than that.
    """
    problem = finished.problem
    log, res = problem.log, _resolutions(problem)
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    x0 = log.y[0]
    draws = []
    for _ in range(refits):
        phase = 0.5 + rng.uniform(-0.5, 0.5, len(res))
        y = np.array([[quantize(v - s, r, p) + s for v, s, r, p in zip(row, x0, res, phase)] for row in sim])
        refit = _Problem(replace(log, y=y), problem.kind, problem.fit, problem.base, problem.instruments,
                         problem.simulator)
        sol = _fit(refit, refit.start)
        draws.append(_finish(refit, sol.x, finished.budget, restarts=False).x)
        finished.refit_simulations += refit.simulations
    return np.array(draws)


def _half_widths(finished: _Finished, sim: np.ndarray, refits: int) -> np.ndarray:
    """Half the width of each 95 % interval (scaled parameters): the wider of the sandwich's ``1.96 se``
    (:func:`_covariance`) and ``t(0.975, refits) * rms`` of the refits' deviations from the estimate
    (:func:`_bootstrap`; none without refits)."""
    from scipy.stats import t as student

    problem = finished.problem
    cov = _covariance(finished.jac, problem.residuals(finished.x), len(problem.log.outputs))
    half = 1.96 * np.sqrt(np.maximum(np.diag(cov), 0.0))
    if refits:
        rms = np.sqrt(np.mean((_bootstrap(finished, sim, refits) - finished.x) ** 2, axis=0))
        half = np.maximum(half, student.ppf(0.975, refits) * rms)
    return half


def _result(finished: _Finished, preset_name: str, simulations: int, refits: int) -> Identification:
    """Estimates with their intervals (:func:`_half_widths`) and the held-out NRMSE of a finished fit."""
    problem = finished.problem
    log = problem.log
    sim = problem.simulate(finished.x, len(log.time))
    half = _half_widths(finished, sim, refits) * problem.scale
    k = problem.n_fit
    params = problem.params(finished.x)
    units = {f.name: f.metadata["unit"] for f in fields(params)}
    out: dict[str, dict[str, Any]] = {}
    for i, n in enumerate(problem.fit):
        value = float(getattr(params, n))
        lo = value - half[i]
        out[n] = {"value": value, "ci95": [max(lo, 0.0) if n in NONNEGATIVE else lo, value + half[i]],
                  "unit": units[n]}
    counts = _largest_counts(problem, finished.x)
    result = Identification(problem.kind, preset_name, out,
                          {o: nrmse(log.y[k:, j], sim[k:, j]) for j, o in enumerate(log.outputs)},
                          float(log.time[k]), 0.0, simulations + finished.refit_simulations, log.display,
                          {f.name: float(getattr(params, f.name)) for f in fields(params)}, log.outputs,
                          log.time, log.y, sim, problem.instruments.input_delay)
    result.largest_residual_counts = {o: float(c) for o, c in zip(log.outputs, counts)}
    result.resolutions = {o: float(r) for o, r in zip(log.outputs, _resolutions(problem))}
    lumped = [n for n in FORCE_PER_VOLT if n in problem.fit]
    if len(lumped) == 1:
        held = " and ".join(n for n in FORCE_PER_VOLT if n not in problem.fit)
        out[lumped[0]]["note"] = (f"with {held} at the preset, {lumped[0]} carries every error of the force per volt "
                                  "amplifier_gain N Kt / (rg Ra)")
    return result


def write_identified(result: Identification, out: Path) -> list[Path]:
    """``out/identified.ssv`` (the identified constants as ``plant.<name>``, for ``--parameter-file``; only for a
    valid fit, :attr:`Identification.valid`) and ``out/identified.png`` (:func:`identified_figure`).

    Returns
    -------
    list of Path
        The files written (the plot only where matplotlib is installed).
    """
    from ipcosim.harness.scenario.ssv import ssv_text

    out.mkdir(parents=True, exist_ok=True)
    written = []
    if result.valid:
        ssv = out / "identified.ssv"
        values = {f"plant.{n}": v["value"] for n, v in result.parameters.items()}
        ssv.write_text(ssv_text(values, name="identified", description=f"{result.plant} plant identified from "
                                                                       f"{result.source}"))
        written.append(ssv)
    from ipcosim.harness.support.extras import optional_figure, require

    if optional_figure(lambda: require("matplotlib") or True, "identified.png") is None:
        return written
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = identified_figure(result)
    fig.savefig(out / "identified.png", dpi=110)
    plt.close(fig)
    return written + [out / "identified.png"]


#: How the plot shows each kind of output: (factor from SI, unit).
_PLOT_UNITS = {"pendulum_angle": (1e3, "mrad")}


def identified_figure(result: Identification) -> Any:
    """The identification's figure: per output, the measured and the simulated reading [mm or mrad] above their
    difference in encoder counts (the fitted part's largest difference in the label, +-0.5 count marked: what the
    true model leaves), the held-out quarter shaded; a fit that is not valid says so in the title."""
    import matplotlib.pyplot as plt

    n = len(result.outputs)
    fig, axes = plt.subplots(2 * n, 1, sharex=True, figsize=(9, 2.1 * 2 * n),
                             gridspec_kw={"height_ratios": [2, 1] * n})
    for j, name in enumerate(result.outputs):
        ax, res = axes[2 * j], axes[2 * j + 1]
        factor, unit = _PLOT_UNITS.get(name, (1e3, "mm"))
        offset = math.pi if name == "pendulum_angle" and abs(result.measured[0, j] - math.pi) < 1 else 0.0
        ax.plot(result.time, (result.measured[:, j] - offset) * factor, lw=0.8, label="measured")
        ax.plot(result.time, (result.simulated[:, j] - offset) * factor, lw=0.8, ls="--",
                label="simulated (identified)")
        ax.set_ylabel(f"{name}{' - pi' if offset else ''}\n[{unit}]", fontsize=8)
        ax.set_title(f"{name}: held-out fit {result.fit[name]:.1%} (1 - NRMSE)", fontsize=8, loc="left")
        counts = (result.measured[:, j] - result.simulated[:, j]) / result.resolutions.get(name, 1.0)
        res.plot(result.time, counts, lw=0.6, color="C3")
        for level in (-0.5, 0.5):
            res.axhline(level, color="k", lw=0.5, ls=":")
        res.set_ylabel("residual\n[counts]", fontsize=8)
        res.set_title(f"measured - simulated; largest over the fitted part "
                      f"{result.largest_residual_counts.get(name, float('nan')):.2f} counts (dotted: +-0.5)",
                      fontsize=8, loc="left")
        for a in (ax, res):
            a.axvspan(result.held_out_from_s, result.time[-1], color="0.9", zorder=-1)
            a.grid(True, alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("time [s] (shaded: held out of the fit)")
    head = f"{result.plant} identified from {Path(result.source).parent.name or result.source}"
    if not result.valid:
        fig.suptitle(f"{head}: NOT VALID, residual {max(result.largest_residual_counts.values()):.1f} counts "
                     f"(> {INVALID_COUNTS:g}): the intervals claim nothing", color="C3", fontsize=10)
    else:
        fig.suptitle(head, fontsize=10)
    fig.tight_layout()
    return fig
