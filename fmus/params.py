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
from dataclasses import dataclass, field, fields, replace
from typing import Any, Mapping

from ipcosim.errors import IpcosimError, closest


class ParameterError(IpcosimError, ValueError):
    """A plant parameter is missing, non-finite or physically impossible."""


class UnknownPresetError(IpcosimError, KeyError):
    """A preset name that does not exist."""

    def __str__(self) -> str:  # KeyError quotes its argument; we want a plain line
        return str(self.args[0]) if self.args else ""


def _p(default: float, unit: str, doc: str, source: str, positive: bool = False,
       nonnegative: bool = False) -> Any:
    return field(default=default, metadata={"unit": unit, "doc": doc, "source": source,
                                            "positive": positive, "nonnegative": nonnegative})


@dataclass(frozen=True)
class MotorParams:
    """Parameters shared by both plants: DC motor, gearbox, pinion, amplifier, gravity."""

    Ra: float = _p(2.6, "Ohm", "armature resistance", "IP02", positive=True)
    La: float = _p(1.8e-4, "H", "armature inductance", "IP02", positive=True)
    Kt: float = _p(7.68e-3, "N.m/A", "motor torque constant", "IP02", positive=True)
    Kb: float = _p(7.68e-3, "V.s/rad", "motor back-EMF constant", "IP02", positive=True)
    Jm: float = _p(3.9e-7, "kg.m2", "rotor moment of inertia", "IP02", nonnegative=True)
    N: float = _p(3.71, "1", "planetary gearbox ratio", "IP02", positive=True)
    rg: float = _p(6.35e-3, "m", "motor pinion radius", "IP02", positive=True)
    g: float = _p(9.81, "m/s2", "gravitational acceleration", "thesis", positive=True)
    voltage_limit: float = _p(10.0, "V", "amplifier/DAC output range: input is clipped to +-voltage_limit",
                              "Q4 data sheet", positive=True)
    coulomb_velocity: float = _p(1e-3, "m/s",
                                 "stick band of the stick-slip Coulomb friction: |v| below it sticks (Karnopp)",
                                 "assumed", positive=True)
    amplifier_gain: float = _p(1.0, "1", "power amplifier's voltage gain: the motor sees amplifier_gain times the "
                                    "clipped command", "IP02 (UPM amplifier, gain 1)", positive=True)

    @property
    def reflected_inertia(self) -> float:
        """Rotor inertia seen at the cart, Jm N^2 / rg^2 [kg]."""
        return self.Jm * self.N ** 2 / self.rg ** 2

    @property
    def force_per_amp(self) -> float:
        """Cart force per armature amp, N Kt / rg [N/A]."""
        return self.N * self.Kt / self.rg

    @property
    def emf_per_velocity(self) -> float:
        """Back-EMF per cart velocity, N Kb / rg [V.s/m]."""
        return self.N * self.Kb / self.rg


@dataclass(frozen=True)
class SingleMassParams(MotorParams):
    """IP02 single-mass cart with a free pendulum (thesis chapter 3)."""

    Mc: float = _p(0.961373, "kg", "cart mass (Meq = Mc + Jm N^2/rg^2 = 1.0945 kg)", "fit", positive=True)
    Mp: float = _p(0.2303, "kg", "pendulum mass", "fit", positive=True)
    Lp: float = _p(0.3371, "m", "full pendulum length (pivot to tip)", "fit", positive=True)
    Beq: float = _p(11.55, "N.s/m", "total viscous damping seen by the cart (rack, bearings, rotor)", "fit",
                    nonnegative=True)
    Bp: float = _p(0.0024, "N.m.s/rad", "viscous damping at the pendulum pivot", "fit", nonnegative=True)
    b: float = _p(0.0, "N", "Coulomb friction force on the cart", "assumed", nonnegative=True)

    @property
    def Meq(self) -> float:
        """Equivalent cart mass including reflected rotor inertia [kg]."""
        return self.Mc + self.reflected_inertia


@dataclass(frozen=True)
class DoubleMassParams(MotorParams):
    """IP02 active cart (motor) coupled by a spring and damper to a passive cart carrying the
    pendulum (thesis chapter 4)."""

    Ma: float = _p(0.961423, "kg", "active cart mass (Ma_eq = Ma + Jm N^2/rg^2 = 1.09455 kg)", "fit",
                   positive=True)
    Mc: float = _p(0.96125, "kg", "passive cart mass", "fit", positive=True)
    Mp: float = _p(0.12717, "kg", "pendulum mass (medium pendulum)", "fit", positive=True)
    Lp: float = _p(0.337, "m", "full pendulum length (pivot to tip)", "fit", positive=True)
    Ba: float = _p(8.347, "N.s/m", "viscous damping on the active cart (incl. rotor damping)", "fit",
                   nonnegative=True)
    Bc: float = _p(0.00201, "N.s/m", "viscous damping on the passive cart", "fit", nonnegative=True)
    Bf: float = _p(2.2029, "N.s/m", "damper between the carts", "fit", nonnegative=True)
    K: float = _p(142.185, "N/m", "spring stiffness between the carts", "fit", nonnegative=True)
    Bp: float = _p(0.0024, "N.m.s/rad", "viscous damping at the pendulum pivot", "fit", nonnegative=True)
    b1: float = _p(0.0, "N", "Coulomb friction force on the active cart", "assumed", nonnegative=True)
    b2: float = _p(0.0, "N", "Coulomb friction force on the passive cart", "assumed", nonnegative=True)

    @property
    def Ma_eq(self) -> float:
        """Equivalent active-cart mass including reflected rotor inertia [kg]."""
        return self.Ma + self.reflected_inertia


PlantParams = SingleMassParams | DoubleMassParams

PLANT_KINDS: dict[str, type] = {"single-mass": SingleMassParams, "double-mass": DoubleMassParams}
#: The plant kinds by name (the one list every room uses).
KINDS: tuple[str, ...] = tuple(PLANT_KINDS)

#: Named presets: (plant kind, overrides of the class defaults, one-line description).
PRESETS: dict[str, tuple[str, dict[str, float], str]] = {
    "thesis-ch3": ("single-mass", {},
                   "single mass, the thesis's MIXED set: the long pendulum's mass (0.2303 kg) on the medium "
                   "pendulum's length (0.3371 m), no real pendulum; kept because it reproduces thesis eq. 3.24 "
                   "and its poles (the thesis's ch. 3 model)"),
    "thesis-appendix-a": ("single-mass", {"Lp": 0.6413},
                          "single mass, long pendulum (0.2303 kg, 0.6413 m), physically consistent: reproduces "
                          "the App. A.2 4-state A, B (the model the thesis designed its LQR on)"),
    "ip02-medium": ("single-mass", {"Mp": 0.12717, "Lp": 0.337},
                    "single mass, medium pendulum (0.12717 kg, 0.337 m: the double-mass fit), physically "
                    "consistent"),
    "thesis-ch4": ("double-mass", {},
                   "double mass, medium pendulum: reproduces thesis eq. 4.23 and App. B.3"),
    # b2 FITTED (not measured): docs/plant.md, thesis-ch4-friction, says how
    "thesis-ch4-friction": ("double-mass", {"b2": 0.1047},
                            "thesis-ch4 plus a passive-cart Coulomb force b2 = 0.1047 N, FITTED so that the "
                            "thesis's double-mass HSMC leaves the thesis's 5.575 mm steady-state error (20 s)"),
}

DEFAULT_PRESET = {"single-mass": "thesis-ch3", "double-mass": "thesis-ch4"}


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
    """Build validated parameters of plant ``kind`` ('single-mass' or 'double-mass')."""
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
    """'single-mass' or 'double-mass'."""
    return "double-mass" if isinstance(params, DoubleMassParams) else "single-mass"
