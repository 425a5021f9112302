"""Identification: the plant's physical parameters from a run's log, with 95 % intervals.

The estimator is an output-error fit of the plant's own model to the logged encoder readings, finished
where the stick-slip friction makes the cost rough (:mod:`.identify_fit`); the estimates carry 95 %
intervals and a held-out check (:mod:`.identify_result`). The bench's computation delay is chosen too, as
the whole number of samples (``DELAY_SAMPLES``) whose trust-region fit leaves the smaller cost: a plant FMU
on the lab bench delays the logged voltage by one sample, the lockstep rig behind the HIL adapter by none.

An identification, one idea to a module:

    identify_log     the log read and checked (read_log, IdentifyError)
    identify_fit     the output-error problem and its solution (trust region, final pass, restarts)
    identify_result  the estimates, their intervals and the held-out fit (Identification)
    identify_report  what it writes: identified.ssv and identified.png
    identify         (this module) the options and the whole identification: identify
"""
from __future__ import annotations

import time as _time
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any, Callable, Sequence

from ipcosim.errors import UsageError, closest
from ipcosim.fmus.instruments import realism
from ipcosim.fmus.kinds import ByKind
from ipcosim.fmus.params import DEFAULT_PRESET, KINDS, PLANT_KINDS, PRESETS, preset
from ipcosim.harness.studies.identify_fit import (
    COVARIANCE_STEP,
    SIMULATION_BUDGET,
    _check_identifiable,
    _finish,
    _fit,
    _Problem,
    simulator,
)
from ipcosim.harness.studies.identify_log import IdentifyError, Log, read_log
from ipcosim.harness.studies.identify_report import identified_figure, write_identified
from ipcosim.harness.studies.identify_result import (
    BOOTSTRAP_REFITS,
    FORCE_PER_VOLT,
    INVALID_COUNTS,
    Identification,
    _result,
    nrmse,
)

#: What the excitation makes identifiable, per plant kind (the default of ``fit``; docs/identify.md, "Parameters"):
#: the carts' masses, dampings and Coulomb forces, the pivot's damping and the motor's torque constant ``Kt``, which
#: stands for the force per volt ``amplifier_gain N Kt / (rg Ra)`` (Kt and Ra are not separable at all: they enter
#: as Kt / Ra and as the armature's time constant La / Ra, 0.07 ms; the amplifier gain and Kb only through that
#: time constant, so they are options).
DEFAULT_FIT = ByKind(lambda k: k.identified)
#: Computation delays tried, in whole samples of the log: the one with the lowest cost is kept (a plant
#: FMU on the lab bench delays the logged voltage by one sample; the lockstep rig behind the adapter does not).
DELAY_SAMPLES = (0, 1)
#: Trust-region evaluations of the refit with the other computation delay (from the first fit's estimate).
DELAY_NFEV = 8


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


__all__ = ["IdentifyOptions", "identify", "DEFAULT_FIT", "DELAY_SAMPLES", "DELAY_NFEV", "IdentifyError", "Log",
           "read_log", "Identification", "nrmse", "simulator", "write_identified", "identified_figure",
           "INVALID_COUNTS", "FORCE_PER_VOLT", "BOOTSTRAP_REFITS", "SIMULATION_BUDGET", "COVARIANCE_STEP"]
