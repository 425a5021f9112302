"""Discrete control laws for the IP02 plants, pure Python (no FMI import): one module per law family.

``base`` (what every law shares and the registry entry ``LawEntry``), ``pid`` (PID and cascade PID),
``lqr``, ``lqg``, ``hsmc`` (HSMC and adaptive HSMC), ``swing_up``, ``excitation`` (the identification
experiment). Each law module holds its law class, its parameters and named sets, its linear model and
its registry entry; ``ipcosim.controllers.catalog`` collects the entries. This package imports none of
them, so a controller FMU carries only its own law's module; :data:`ENTRIES` says where each entry is
declared, so that one law's entry is found without importing the others (:func:`declared`).

Every law is a small class with explicit state:

* ``step(measurements, reference) -> voltage`` is called once per sample instant k T with the
  plant's measured positions (``ipcosim.fmus.physics.MEASURED[kind]`` order: cart position and pendulum
  angle for the single mass; active cart, passive cart and pendulum angle for the double mass)
  and the reference position of the motor-driven cart; it returns the voltage to hold until the
  next instant, already limited to ``+-voltage_limit``.
* ``reset()`` returns the law to its initial state (the first ``step`` initializes the velocity
  estimates from the first measurement, so the output at t = 0 is defined by the inputs at t = 0).
* ``sample_period`` [s] and ``voltage_limit`` [V] are attributes.

A law never reads a true velocity: velocities come from filtered differentiation
(``FilteredDerivative``) or from the LQR's observer. Laws with an integrator stop integrating
while the output is saturated in the direction the integrator pushes (conditional integration,
the clamping anti-windup).

Sign conventions (``ipcosim.fmus.physics``): a positive voltage pushes the motor cart towards +x; the
pendulum angle is counter-clockwise from upright, so pushing the cart towards +x makes the
angle grow, and the pendulum leans towards +x for a *negative* angle.
"""
from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ipcosim.controllers.laws.base import LawEntry

#: Where each law's registry entry is declared, by the law's name: (its module of this package, the entry's name
#: there), in the order the evidence tables and the native build list the laws (``ipcosim.controllers.catalog``).
ENTRIES: dict[str, tuple[str, str]] = {
    "PID": ("pid", "PID_LAW"), "CascadePID": ("pid", "CASCADE_PID_LAW"), "LQR": ("lqr", "LQR_LAW"),
    "HSMC": ("hsmc", "HSMC_LAW"), "AdaptiveHSMC": ("hsmc", "ADAPTIVE_HSMC_LAW"), "LQG": ("lqg", "LQG_LAW"),
    "SwingUp": ("swing_up", "SWING_UP_LAW"), "Excitation": ("excitation", "EXCITATION_LAW")}


def declared(law: str) -> LawEntry | None:
    """The registry entry of the law named ``law``, importing its module alone; None when no law has that name.

    Parameters
    ----------
    law : str
        A key of :data:`ENTRIES` (``LQR``).
    """
    if law not in ENTRIES:
        return None
    module, name = ENTRIES[law]
    return getattr(importlib.import_module(f"{__name__}.{module}"), name)
