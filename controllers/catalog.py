"""The registry of the control laws: each law's entry (``ipcosim.controllers.laws``, one module per law
family) looked up by name -- its parameters (names, units, defaults), its named parameter sets, and the
factory that builds it from flat parameter values, the same values a controller FMU holds.

Each law has a ``thesis`` set (the thesis's numbers: its sections 3.2 and 4.2, App. A and B) and,
where the thesis's numbers do not do the task on the thesis's own model (move the motor-driven
cart 0.05 m within 10 s, |angle| < 0.35 rad, within +-10 V), a ``tuned`` set that does
(``ipcosim.controllers.tuning`` says how it was found; docs/controllers.md says why it was needed). The
numbers live in the law modules.

=============  ===========================  =========================================
law            single mass                  double mass
=============  ===========================  =========================================
PID            thesis (fails: by design)    thesis (fails: by design)
CascadePID     tuned (no thesis set)        tuned (no thesis set)
LQR            thesis; discrete             thesis; discrete
HSMC           tuned; thesis (too slow)     thesis; tuned (robust: lab bench)
AdaptiveHSMC   tuned; thesis (too slow)     thesis
LQG            tuned; lab (not in thesis)   tuned; lab (not in thesis)
=============  ===========================  =========================================

The first set listed is the default: the FMU parameter defaults are its values, and the SSP
scenarios bind it (``parameter_sets`` feeds their ``.ssv`` files: docs/master.md).

Flat parameter names (``schema``): the law's gains as in its module of ``ipcosim.controllers.laws``; ``sample_period``
[s]; ``voltage_limit`` [V]; for the model-based laws (LQR, LQG, HSMC, AdaptiveHSMC) the design model's
physical constants as ``model_<name>`` (``ipcosim.fmus.params`` names, defaults = the plant kind's default
preset): the controller's *belief* about the plant, independent of the plant component.

Adding a law: one module in ``ipcosim.controllers.laws`` declaring its ``LawEntry``, listed in
``ipcosim.controllers.laws.ENTRIES`` (``REGISTRY`` below collects them); its FMU scripts
(``controllers/fmu_<law>_<plant>.py``); its scenario row (``ipcosim.harness.scenario.scenarios``).
"""
from __future__ import annotations

import sys
from types import ModuleType
from typing import Any

from ipcosim.controllers.laws import ENTRIES, base, declared
from ipcosim.controllers.laws.base import (
    PLANT_SUFFIX,
    CatalogError,
    DiscreteLaw,
    LawEntry,
    ParamSpec,
)
from ipcosim.errors import closest
from ipcosim.fmus.params import DEFAULT_PRESET, KINDS, PlantParams

#: Every law by name, in the order the evidence tables and the native build list them.
REGISTRY: dict[str, LawEntry] = {e.name: e for e in map(declared, ENTRIES)}
#: The control laws on both plants (the swing-up runs on the single mass only; the excitation is no control law).
LAWS = tuple(name for name, e in REGISTRY.items() if e.feedback and set(e.sets) == set(KINDS))
#: Parameter sets per law and plant kind; the first is the default (the one that does the task).
PARAMETER_SETS: dict[str, dict[str, tuple[str, ...]]] = {name: dict(e.sets) for name, e in REGISTRY.items()}
#: Laws whose gains the design stack computes, shipped designed for the defaults and parameters of
#: their FMU (the swing-up hands over to an LQR).
DESIGNED_LAWS = tuple(name for name, e in REGISTRY.items() if e.designed is not None)
_BY_CLASS = {cls: e for e in REGISTRY.values() for cls in e.classes}


def entry(law: str) -> LawEntry:
    """The registry entry of the law named ``law`` (``CatalogError`` naming the closest if unknown)."""
    try:
        return REGISTRY[law]
    except KeyError:
        raise CatalogError("law", f"unknown control law {law!r}; {closest(law, REGISTRY)}") from None


def entry_of(law: DiscreteLaw) -> LawEntry | None:
    """The registry entry of a law object (by its class, or the nearest registered base class)."""
    return next((_BY_CLASS[cls] for cls in type(law).__mro__ if cls in _BY_CLASS), None)


def law_modules() -> tuple[ModuleType, ...]:
    """The modules the laws run in: the base module and every registered law's module."""
    return tuple(dict.fromkeys([base, *(sys.modules[cls.__module__] for e in REGISTRY.values() for cls in e.classes)]))


def _checked(kind: str, law: str) -> LawEntry:
    e = entry(law)
    e.check(kind)
    return e


def model_name(kind: str, law: str) -> str:
    """FMU model name ``<Law><Plant>``, e.g. ``LQRSingleMass``."""
    return f"{law}{PLANT_SUFFIX[kind]}"


def default_preset(kind: str) -> str:
    """The plant preset a controller is designed for unless told otherwise."""
    return DEFAULT_PRESET[kind]


def default_set(kind: str, law: str) -> str:
    """The parameter set used when none is named."""
    return PARAMETER_SETS[law][kind][0]


def schema(kind: str, law: str) -> list[ParamSpec]:
    """Every parameter of ``law`` on ``kind``, with the default set's values as defaults."""
    return _checked(kind, law).schema(kind)


def set_values(kind: str, law: str, parameter_set: str) -> dict[str, Any]:
    """The values a named parameter set gives (only the parameters it fixes)."""
    return _checked(kind, law).set_values(kind, parameter_set)


def parameter_sets(kind: str, law: str) -> dict[str, dict[str, Any]]:
    """``{set name: {FMU parameter: value}}`` of ``law`` on plant ``kind``.

    The scenarios' ``.ssv`` files hold these values (docs/controllers.md, FMUs).
    """
    return {name: set_values(kind, law, name) for name in PARAMETER_SETS[law][kind]}


def defaults(kind: str, law: str) -> dict[str, Any]:
    """``{name: default}`` of every parameter (``schema``)."""
    return {s.name: s.default for s in schema(kind, law)}


def build_law(kind: str, law: str, values: dict[str, Any] | None = None, backend: str = "control") -> DiscreteLaw:
    """A law from flat parameter values (missing ones take their defaults).

    Parameters
    ----------
    law : str
        One of ``PARAMETER_SETS``.
    kind : {'single-mass', 'double-mass'}
        Plant kind.
    values : mapping, optional
        ``{parameter: value}`` (``schema`` names).
    backend : {'control', 'scipy'}
        Design back end of the LQR (the FMUs use ``scipy``).

    Raises
    ------
    ControllerParameterError
        Naming the parameter (``parameter`` attribute and the message).
    """
    return entry(law).make(kind, values, backend)


def make_law(kind: str, law: str, parameter_set: str | None = None, design_params: PlantParams | None = None,
             sample_period: float = 1e-3, voltage_limit: float = 10.0, backend: str = "control",
             **overrides: Any) -> DiscreteLaw:
    """A law from a named parameter set (default: the first of ``PARAMETER_SETS``).

    Parameters
    ----------
    kind, law : str
        Plant kind and law.
    parameter_set : str, optional
        ``thesis`` or ``tuned``.
    design_params : PlantParams, optional
        Plant parameters the model-based laws are designed for (default: the kind's default preset).
    sample_period, voltage_limit : float
        [s], [V].
    backend : str
        LQR design back end.
    **overrides
        Further flat parameter values (``schema`` names), e.g. ``use_thesis_coefficients=True``.
    """
    e = _checked(kind, law)
    values: dict[str, Any] = dict(e.set_values(kind, parameter_set or e.default_set(kind)))
    values.update(sample_period=sample_period, voltage_limit=voltage_limit)
    if design_params is not None and e.model_based:
        names = {s.name for s in e.schema(kind)}
        for k2, val in vars(design_params).items():
            if f"model_{k2}" in names:
                values[f"model_{k2}"] = val
    values.update(overrides)
    return e.make(kind, values, backend)


# ============================================================ every law with designed gains

def _designed(law: str) -> Any:
    designed = entry(law).designed
    if designed is None:
        raise CatalogError("law", f"control law {law} has no designed gains (those that have: "
                                  f"{', '.join(DESIGNED_LAWS)})")
    return designed


def gain_specs(kind: str, law: str) -> list[ParamSpec]:
    """The gain parameters of a law of ``DESIGNED_LAWS``."""
    return _designed(law).gain_specs(kind)


def weight_parameters(kind: str, law: str) -> tuple[str, ...]:
    """The parameters of a designed law that enter only through the design (weights, poles, noises)."""
    return _designed(law).weight_parameters(kind)


def design_parameters(kind: str, law: str) -> tuple[str, ...]:
    """Every parameter a designed law's gains depend on: weights, ``model_*``, ``sample_period``."""
    _designed(law)
    return entry(law).design_parameters(kind)


def designed_gains(law: DiscreteLaw) -> dict[str, float]:
    """The gains (``gain_specs`` names) of a designed law object (a swing-up: its balancing LQR's)."""
    e = entry_of(law)
    if e is None or e.designed is None:
        raise CatalogError("law", f"the law {type(law).__name__} has no designed gains")
    return e.designed.gains(law)


def law_from_gains(kind: str, law: str, values: dict[str, Any], gains: dict[str, float]) -> DiscreteLaw:
    """A designed law from flat values and given gains, without the design stack."""
    return _designed(law).from_gains(kind, values, gains)


__all__ = ["REGISTRY", "LAWS", "KINDS", "PARAMETER_SETS", "DESIGNED_LAWS", "ParamSpec", "LawEntry", "CatalogError",
           "entry", "entry_of", "law_modules", "schema", "set_values", "parameter_sets", "defaults",
           "build_law", "make_law", "model_name", "default_set", "default_preset", "gain_specs", "weight_parameters",
           "design_parameters", "designed_gains", "law_from_gains"]
