"""The co-simulation run spec: one scenario, run through the master (``ipcosim.prepare``).

Made in the parent from the scenario (parsed and bound, nothing extracted) so that
``--vary`` and ``--params`` are checked against the scenario's real parameters; each worker
calls :meth:`CosimSpec.build` once, which loads the scenario and extracts its FMUs into the
worker's temporary folder, and then runs it once per case with the case's values as start
values (``--set`` semantics).
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ipcosim.harness.studies.runners import RunFailure, Runner, RunSpec

#: Extra result columns of a co-simulation run beyond the task metrics and cost terms.
TIMING_METRICS = ("wall_time_s", "real_time_factor", "loop_real_time_factor")


def _no_slave(instance: Any) -> Any:  # pragma: no cover - never called: binding only
    raise RuntimeError("binding only")


def _hash_files(paths: list[Path]) -> str:
    h = hashlib.sha256()
    for p in paths:
        h.update(p.name.encode())
        if p.is_dir():
            for f in sorted(q for q in p.rglob("*") if q.is_file()):
                h.update(str(f.relative_to(p)).encode())
                h.update(f.read_bytes())
        elif p.exists():
            h.update(p.read_bytes())
    return h.hexdigest()[:16]


@dataclass
class CosimSpec(RunSpec):
    """One scenario, run by the co-simulation master.

    Attributes
    ----------
    location : str
        Absolute path of the scenario folder or ``.ssp`` archive (what workers load).
    stop_time, step : float or None
        Experiment overrides (None: the scenario's).
    set : dict
        ``component.variable`` start values applied in every run.
    with_series : bool
        Also return the run's signals (thinned) under ``series``.
    parameter_set : str or None
        A named parameter set of the scenario (``thesis``, ``tuned``) instead of its default.
    """

    location: str = ""
    stop_time: float | None = None
    step: float | None = None
    set: dict = field(default_factory=dict)
    with_series: bool = False
    parameter_set: str | None = None
    gains: str = ""
    name: str = ""
    scenario_hash: str = ""
    parameters: Mapping[str, Any] = field(default_factory=dict)
    metric_names: tuple[str, ...] = ()
    fmu_files: dict = field(default_factory=dict)
    archive: bytes | None = field(default=None, repr=False)
    fmus: str = "python"

    @classmethod
    def from_scenario(cls, scenario: str, stop_time: float | None = None, step: float | None = None,
                      set: Mapping[str, Any] | None = None, series: bool = False,
                      parameter_set: str | None = None, fmus: str = "python") -> "CosimSpec":
        """Parse and bind a scenario (FMUs are not extracted here) and describe its runs.

        Raises
        ------
        IpcosimError
            Unknown scenario, unreadable SSD/FMU, unknown ``--set`` names (one line each).
        """
        from ipcosim.fmus.metrics import BOUND_KEYS, METRIC_KEYS, PASSIVE_RESIDUAL_KEYS
        from ipcosim.harness.api.engine import Prepared
        from ipcosim.harness.scenario.values import with_set
        from ipcosim.harness.studies.cost import COST_TERMS

        prepared = Prepared(scenario, parameter_set=parameter_set, slave_factory=_no_slave, warn=False, fmus=fmus)
        system = prepared.system
        set = dict(set or {})
        with_set(system, set)  # unknown or unsettable names: one clear line
        params: dict[str, Any] = {}
        files: list[Path] = [prepared.scenario.location]
        for inst in system.instances:
            for var in inst.model.variables.values():
                if var.causality == "parameter" and var.type in ("Real", "Integer") and var.settable:
                    params[f"{inst.name}.{var.name}"] = inst.start_value(var.name)
            if inst.model.path is not None:
                files.append(inst.model.path)
        fmu_files = {c.source: str(system.instance(c.name).model.path) for c in prepared.scenario.components
                     if system.instance(c.name).model.path is not None}
        params.update(set)
        exp = prepared.scenario.experiment
        spec = cls(location=str(Path(prepared.scenario.location).resolve()),
                   stop_time=stop_time if stop_time is not None else exp.stop_time,
                   step=step if step is not None else exp.step_size, set=set, with_series=series,
                   parameter_set=parameter_set,
                   gains=parameter_set or ",".join(prepared.scenario.bound_sets) or "FMU defaults",
                   name=prepared.scenario.name or Path(scenario).name,
                   scenario_hash=_hash_files(files), parameters=params,
                   metric_names=tuple(METRIC_KEYS) + PASSIVE_RESIDUAL_KEYS + BOUND_KEYS + COST_TERMS + TIMING_METRICS,
                   fmu_files=fmu_files, fmus=fmus)
        return spec

    def portable(self) -> "CosimSpec":
        """A copy that carries the scenario as an ``.ssp`` archive (SSD, parameter sets and every
        FMU), so that workers on other machines need no files of this one. The archive is made
        in memory; the copy's ``key`` is the same as this spec's."""
        import dataclasses
        import io
        import zipfile

        if self.archive is not None:
            return self
        location = Path(self.location)
        if location.is_file():
            data = location.read_bytes()
        else:
            buf = io.BytesIO()
            with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as zf:
                for f in sorted(location.iterdir()):
                    if f.is_file() and (f.name == "SystemStructure.ssd" or f.suffix == ".ssv"):
                        zf.write(f, f.name)
                for source, path in self.fmu_files.items():
                    zf.write(path, source)
            data = buf.getvalue()
        return dataclasses.replace(self, archive=data)

    def identity(self) -> dict[str, Any]:
        # "overrides" is the stored key of the --set values in a sweep's metadata.json (a file format that
        # resumed sweeps and other tools read), kept under that name.
        out = {"name": self.name, "scenario_hash": self.scenario_hash, "location": self.location,
               "stop_time": self.stop_time, "step": self.step, "overrides": self.set,
               "parameter_set": self.parameter_set, "with_series": self.with_series}
        if self.fmus != "python":
            out["fmus"] = self.fmus
        return out

    def build(self) -> Runner:
        """Load the scenario and extract its FMUs (once per worker); return the run function."""
        from ipcosim.harness.api.engine import Prepared

        location = self.location
        if self.archive is not None:  # the archive's bytes travelled with the spec: a local copy
            import atexit
            import shutil
            import tempfile

            folder = tempfile.mkdtemp(prefix="ipcosim-ssp-")
            atexit.register(shutil.rmtree, folder, True)
            location = str(Path(folder) / f"{Path(self.location).stem or 'scenario'}.ssp")
            Path(location).write_bytes(self.archive)
        holder = [Prepared(location, parameter_set=self.parameter_set, warn=False, fmus=self.fmus,
                           reuse_instances=True)]  # many runs per worker: reset, not re-instantiate
        spec = self

        def release() -> None:
            # Unload the FMUs before the interpreter starts tearing itself down: left to the
            # final garbage collection, unloading them at exit can corrupt the heap.
            import gc

            if holder:
                holder.pop().close()
                gc.collect()

        import atexit

        atexit.register(release)

        def run(params: Mapping[str, float], seed: int) -> dict:
            if not holder:
                raise RunFailure(f"{spec.name}: the runner was released")
            values = {**spec.set, **params}
            return spec.row_of(holder[0].run(stop_time=spec.stop_time, step=spec.step, set=values,
                                             raise_on_error=False))

        return run

    def row_of(self, result: Any) -> dict[str, Any]:
        """A run's row: its task metrics, the cost terms of its position, reference, angle and
        voltage, and (``with_series``) the series for the report.

        Raises
        ------
        RunFailure
            A result without those columns, or a run cut short before the pendulum fell.
        """
        from ipcosim.fmus.metrics import (
            ANGLE_COLUMNS,
            POSITION_COLUMNS,
            REFERENCE_COLUMNS,
            VOLTAGE_COLUMNS,
            first_column,
        )
        from ipcosim.harness.studies.cost import cost_terms, series

        data = result.data
        cols = result.columns
        names = [first_column(cols, c) for c in (POSITION_COLUMNS, REFERENCE_COLUMNS, ANGLE_COLUMNS,
                                                 VOLTAGE_COLUMNS)]
        metrics = {k: v for k, v in result.metrics.items() if k in self.metric_names}
        if None in names or len(data) < 2:
            raise RunFailure(result.error or f"{self.name}: the result lacks the position, reference, angle "
                                             f"or voltage column")
        signals = [np.asarray(data[n], dtype=float) for n in names]
        t = np.asarray(data["time"], dtype=float)
        metrics.update(cost_terms(t, *signals))
        if result.error is not None:
            # a run cut short: a result if the pendulum had fallen by then, else a failure
            if metrics.get("fall_time_s") is None:
                raise RunFailure(result.error)
            metrics["upright"] = False
            metrics["error"] = result.error
        if self.with_series:
            metrics["series"] = series(t, *signals)
        return metrics
