"""Redesign: the native flavour's parameter values for a set of Python-flavour parameter values.

The native controllers take the numbers the Python design computes (LQR gains, discretized
observer and filter matrices, the HSMC's top-layer constants) as parameters; the native plants
take the integrator's stage matrices. :func:`redesign` recomputes all of them with the same
Python design code from the Python flavour's parameters (weights, poles, design model, physical
constants), which is how ``ipcosim`` runs a scenario whose parameter set was written for the
Python flavour on native FMUs, and how a user writes a native parameter set for a new design::

    from ipcosim.harness.native.redesign import redesign
    values = redesign("build/fmus-native/LQRSingleMass.fmu", {"R": 0.05})   # {native name: value}
"""
from __future__ import annotations

import functools
import json
import zipfile
from pathlib import Path
from typing import Any, Mapping

from ipcosim.errors import IpcosimError, closest
from ipcosim.fmus.instruments import delay_steps


class NativeParameterError(IpcosimError, KeyError):
    """A parameter the native flavour does not have (names the model and the flavour).

    ``parameter``: the name it lacks, where one parameter is meant (else None); ``design_only``: that name
    is a design parameter of the Python flavour only (its native FMU takes the designed numbers instead).
    """

    def __init__(self, message: str, parameter: str | None = None, design_only: bool = False) -> None:
        super().__init__(message)
        self.parameter = parameter
        self.design_only = design_only

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


def native_info(fmu: Path | str) -> dict[str, Any] | None:
    """The ``resources/native.json`` of a native FMU, or None for any other FMU."""
    try:
        with zipfile.ZipFile(fmu) as z:
            return json.loads(z.read("resources/native.json"))
    except (KeyError, zipfile.BadZipFile, FileNotFoundError, IsADirectoryError):
        return None


def redesign(fmu: Path | str | Mapping[str, Any], python_values: Mapping[str, Any]) -> dict[str, float]:
    """Native parameter values implied by Python-flavour parameter values (others at their defaults).

    Parameters
    ----------
    fmu : path or mapping
        A native FMU (or its ``native.json`` content).
    python_values : mapping
        ``{Python-flavour parameter: value}``.

    Returns
    -------
    dict
        ``{native parameter: value}`` for every parameter the redesign computes, plus the given
        values of parameters both flavours share.
    """
    info = fmu if isinstance(fmu, Mapping) else native_info(fmu)
    if info is None:
        raise NativeParameterError(f"{fmu} is not a native ipcosim FMU")
    role = info["role"]
    if role == "plant":
        check_instruments(info, python_values)
    if role not in ("law", "plant") or unchanged(info, python_values):
        return {k: v for k, v in python_values.items() if k not in info.get("python_only", ())}
    if role == "law":
        return _law(info, python_values)
    return _plant(info, python_values)


def unchanged(info: Mapping[str, Any], python_values: Mapping[str, Any]) -> bool:
    """Whether ``python_values`` leave every design parameter at the value the native FMU was built
    with (``design_values`` of its ``native.json``): then its parameters' defaults are already the
    design's numbers and nothing is redesigned (nor the design code imported)."""
    built = info.get("design_values")
    if built is None:
        return False
    step, python_only = info.get("integrator_step"), set(info.get("python_only", ()))
    for name, value in python_values.items():
        if name == "integrator_step" and step is not None:
            reference = float(step)
        elif name in built:
            reference = built[name]
        elif name in python_only:
            return False  # a design input the build did not record: the redesign decides
        else:
            continue
        try:
            if float(value) != float(reference):
                return False
        except (TypeError, ValueError):
            return False
    return True


def _law(info: Mapping[str, Any], values: Mapping[str, Any]) -> dict[str, float]:
    from ipcosim.controllers.catalog import defaults
    from ipcosim.harness.native.leaves import numbers
    from ipcosim.harness.native.models import native_law

    full = dict(defaults(info["plant"], info["law"]))
    full.update(values)
    law = native_law(info["plant"], info["law"], full)
    nums = numbers(law)
    out = {name: nums[path] for path, name in info["paths"].items()}
    for name in ("sample_period", "voltage_limit"):
        out[name] = float(full[name])
    for name, value in values.items():
        if name not in info["python_only"]:
            out.setdefault(name, value)
    return out


@functools.lru_cache(maxsize=64)
def _stages(L: tuple[tuple[float, ...], ...], step: float) -> list[Any]:
    """``etdrk4_f_form(L, step)``, remembered: the stiff part moves only with the parameters of the armature
    circuit and of the mass it drives, and an identification redesigns for thousands of parameter sets."""
    from ipcosim.fmus.integrator import etdrk4_f_form

    return etdrk4_f_form(L, step)


def _plant(info: Mapping[str, Any], values: Mapping[str, Any]) -> dict[str, float]:
    from ipcosim.fmus.params import DEFAULT_PRESET, PLANT_KINDS, PRESETS, make
    from ipcosim.fmus.plant import Plant
    from ipcosim.harness.native.models import stage_coefficients

    kind = info["plant"]
    fields = set(PLANT_KINDS[kind].__dataclass_fields__)
    phys = dict(PRESETS[DEFAULT_PRESET[kind]][1])
    phys.update({k: float(v) for k, v in values.items() if k in fields})
    step = float(values.get("integrator_step", float(info["integrator_step"])))
    out: dict[str, float] = {k: v for k, v in values.items()}
    plant = Plant(make(kind, **phys))
    present = set(info["stage_coefficients"])
    L = tuple(tuple(row) for row in plant._L)
    for name, value in stage_coefficients(_stages(L, step), len(plant.state_names)).items():
        if name in present:
            out[name] = value
        elif value != 0.0:
            raise NativeParameterError(f"the native flavour of {info['model']} has no integrator coefficient {name} "
                                       f"(0 in its generated code), but these parameters make it {value!r}: "
                                       f"{PYTHON_FLAVOUR}")
    out["integrator_step"] = step
    return out


#: Where such a run goes instead (``ipcosim export`` has no flavour option: it exports native FMUs only).
PYTHON_FLAVOUR = "`ipcosim run --fmus python` runs it"


def check_instruments(info: Mapping[str, Any], values: Mapping[str, Any]) -> None:
    """Raise NativeParameterError for an instrument option of the Python plant the native plant lacks set to
    a value other than 0 (``ipcosim.harness.native.models.NATIVE_INSTRUMENTS_OFF``: measurement noise), or for a
    computation delay longer than the native plant's delay line."""
    for name in info.get("instruments_off", ()):
        if name in values and float(values[name]) != 0.0:
            raise NativeParameterError(
                f"the native flavour of {info['model']} has no {name}: parameter {name} = {values[name]} must "
                f"be 0 there (measurement noise is in the python flavour only: {PYTHON_FLAVOUR})")
    longest = int(info.get("max_delay_steps", 0))
    step = float(values.get("integrator_step", info["integrator_step"]))
    if "input_delay" in values and delay_steps(float(values["input_delay"]), step) > longest:
        raise NativeParameterError(
            f"the native flavour of {info['model']} delays the voltage by at most {longest} steps of {step:g} s: "
            f"parameter input_delay = {values['input_delay']} is longer ({PYTHON_FLAVOUR})")


def check_settable(info: Mapping[str, Any], fmu_name: str, names: list[str], known: set[str]) -> None:
    """Raise NativeParameterError for the first of ``names`` the native flavour lacks."""
    for name in names:
        if name not in known:
            extra = " (a design parameter of the python flavour only: the native flavour takes the numbers " \
                    f"the design computes; {PYTHON_FLAVOUR}, or see docs/native.md to redesign)" \
                if name in info.get("python_only", ()) else ""
            near = "" if extra else f"; {closest(name, known)}"
            raise NativeParameterError(f"the native flavour of {fmu_name} has no parameter {name!r}{extra}{near}",
                                       parameter=name, design_only=bool(extra))
