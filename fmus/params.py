"""Physical parameters of the IP02 plants, as named presets.

Every value carries its unit and its source. Sources:

* ``IP02``   -- Quanser IP02 documentation (motor, gearbox, pinions, encoders); the
  thesis's matrices confirm these constants.
* ``fit``    -- least-squares fit of the remaining constants (masses, viscous
  damping, pendulum length) to the thesis's linearized matrices; the fitted sets
  reproduce eq. 3.24, App. A.2, eq. 4.23 and App. B.3 (see ``docs/plant.md``).
* ``assumed`` -- not given by the thesis (Coulomb friction is unknown: default 0).

The plant equations (``ipcosim.fmus.physics``) use the parameters exactly as named here.
Derived quantities (e.g. the equivalent cart mass including the reflected rotor
inertia) are properties, never stored twice.
"""
from __future__ import annotations

import math
from dataclasses import fields, replace
from typing import Any, Iterator, Mapping, Sequence

from ipcosim.errors import IpcosimError, closest
from ipcosim.fmus import kinds
from ipcosim.fmus.kinds.double_mass import DoubleMassParams
from ipcosim.fmus.kinds.single_mass import SingleMassParams


class ParameterError(IpcosimError, ValueError):
    """A plant parameter is missing, non-finite or physically impossible."""


class UnknownPresetError(IpcosimError, KeyError):
    """A preset name that does not exist."""

    def __str__(self) -> str:  # KeyError quotes its argument; we want a plain line
        return str(self.args[0]) if self.args else ""


PlantParams = SingleMassParams | DoubleMassParams

#: The parameter class of each plant kind (``ipcosim.fmus.kinds``).
PLANT_KINDS: Mapping[str, type] = kinds.ByKind(lambda k: k.params)
#: The plant kinds by name (the one list every room uses).
KINDS: Sequence[str] = kinds.KindNames()


class _Presets(Mapping[str, tuple[str, dict[str, float], str]]):
    """Every kind's named presets: name -> (plant kind, overrides of the class defaults, one-line description)."""

    def _all(self) -> dict[str, tuple[str, dict[str, float], str]]:
        return {name: (k, values, doc) for k in kinds.names() for name, (values, doc) in kinds.get(k).presets.items()}

    def __getitem__(self, name: str) -> tuple[str, dict[str, float], str]:
        return self._all()[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._all())

    def __len__(self) -> int:
        return len(self._all())


#: Named presets (declared by the kind modules): (plant kind, overrides of the class defaults, description).
PRESETS: Mapping[str, tuple[str, dict[str, float], str]] = _Presets()

#: The default preset of each plant kind (the plant FMU's parameter defaults).
DEFAULT_PRESET: Mapping[str, str] = kinds.ByKind(lambda k: k.default_preset)


def parameter_info(cls: type) -> list[dict[str, Any]]:
    """Name, default, unit, description and source of every parameter of a params class.

    Parameters
    ----------
    cls : type
        ``SingleMassParams`` or ``DoubleMassParams``.

    Returns
    -------
    list of dict
        One dict per parameter with keys ``name``, ``default``, ``unit``, ``doc``, ``source``.
    """
    return [{"name": f.name, "default": f.default, "unit": f.metadata["unit"],
             "doc": f.metadata["doc"], "source": f.metadata["source"]} for f in fields(cls)]


def validate(params: PlantParams) -> PlantParams:
    """Check every parameter for finiteness and sign; return ``params`` unchanged.

    Raises
    ------
    ParameterError
        Naming the first offending parameter and its value.
    """
    for f in fields(params):
        value = getattr(params, f.name)
        if not isinstance(value, (int, float)) or isinstance(value, bool):
            raise ParameterError(f"parameter {f.name} must be a number, got {value!r}")
        if not math.isfinite(value):
            raise ParameterError(f"parameter {f.name} = {value} is not finite")
        if f.metadata.get("positive") and value <= 0:
            raise ParameterError(f"parameter {f.name} = {value} {f.metadata['unit']} must be > 0 "
                                 f"({f.metadata['doc']})")
        if f.metadata.get("nonnegative") and value < 0:
            raise ParameterError(f"parameter {f.name} = {value} {f.metadata['unit']} must be >= 0 "
                                 f"({f.metadata['doc']})")
    return params


def preset(name: str, **overrides: float) -> PlantParams:
    """Return the validated parameter set of a named preset, with optional overrides.

    Parameters
    ----------
    name : str
        One of ``PRESETS`` (``thesis-ch3``, ``thesis-appendix-a``, ``thesis-ch4``).
    **overrides : float
        Parameter values replacing the preset's.

    Raises
    ------
    UnknownPresetError
        If ``name`` is not a preset.
    ParameterError
        If an override names no parameter or has an invalid value.
    """
    if name not in PRESETS:
        raise UnknownPresetError(f"unknown preset {name!r}; {closest(name, PRESETS)}")
    kind, values, _ = PRESETS[name]
    return make(kind, **{**values, **overrides})


def make(kind: str, **values: float) -> PlantParams:
    """Build validated parameters of plant ``kind`` (a name of ``ipcosim.fmus.kinds``)."""
    if kind not in PLANT_KINDS:
        raise ParameterError(f"unknown plant kind {kind!r}; {closest(kind, PLANT_KINDS)}")
    cls = PLANT_KINDS[kind]
    names = {f.name for f in fields(cls)}
    for key in values:
        if key not in names:
            raise ParameterError(f"{kind} plant has no parameter {key!r}; {closest(key, names)}")
    return validate(cls(**{k: float(v) for k, v in values.items()}))


def with_values(params: PlantParams, values: Mapping[str, float]) -> PlantParams:
    """Return a validated copy of ``params`` with some values replaced."""
    names = {f.name for f in fields(params)}
    for key in values:
        if key not in names:
            raise ParameterError(f"plant has no parameter {key!r}; {closest(key, names)}")
    return validate(replace(params, **{k: float(v) for k, v in values.items()}))


def plant_kind_of(params: PlantParams) -> str:
    """The plant kind's name of a parameter set (``ipcosim.fmus.kinds.UnknownKindError`` if none declares its class)."""
    return kinds.of_params(params).name
