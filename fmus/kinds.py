"""Which plant is this: the plant FMUs' model names and the plant kind of a scenario or component.

The kinds are those of :data:`ipcosim.fmus.params.KINDS`. A study, the native generator, the loop
analysis and the ``hil`` swap alias all ask the same question, and :func:`plant_kind` is the one
answer. (Not packed into the FMUs: no FMU script imports it.)
"""
from __future__ import annotations

from typing import Iterable

#: Model name of each plant FMU -> its plant kind.
PLANT_MODELS: dict[str, str] = {"IP02SingleMass": "single-mass", "IP02DoubleMass": "double-mass"}

#: Connectors that only the double-mass plant has, and the single-mass plant's cart position.
DOUBLE_MASS_CONNECTORS = ("active_cart_position", "passive_cart_position")
SINGLE_MASS_CONNECTORS = ("cart_position",)
#: The connector of the cart that carries the pendulum, by plant kind (the double mass's pendulum sits on
#: its passive cart, the one the spring couples to the motor-driven cart).
PENDULUM_CART: dict[str, str] = {"single-mass": "cart_position", "double-mass": "passive_cart_position"}


def plant_kind(name: str = "", model: str | None = None, connectors: Iterable[str] = (),
               parameters: Iterable[str] | None = None) -> str | None:
    """The plant kind (``single-mass`` or ``double-mass``) of a scenario or of its plant component.

    Asked in this order, the first that knows answers: the plant FMU's ``model`` name
    (:data:`PLANT_MODELS`); the scenario's ``name`` (or path), which holds the kind in the project's
    names (``double-mass-lqr``, ``pure:single-mass-lqr``); the plant's ``connectors``; the plant's
    ``parameters`` (the double-mass cart alone has the spring ``K``; any other set is single-mass).

    Parameters
    ----------
    name : str
        Scenario name or path.
    model : str, optional
        Model name of the plant component's FMU.
    connectors : iterable of str
        Connector names of the plant component.
    parameters : iterable of str, optional
        Parameter names of the plant component (``K``, ``Mp``...); None: not asked.

    Returns
    -------
    str or None
        The kind, or None when none of these tells it.
    """
    if model in PLANT_MODELS:
        return PLANT_MODELS[model]
    for kind in PLANT_MODELS.values():
        if kind in name:
            return kind
    connectors = set(connectors)
    if connectors.intersection(DOUBLE_MASS_CONNECTORS):
        return "double-mass"
    if connectors.intersection(SINGLE_MASS_CONNECTORS):
        return "single-mass"
    if parameters is not None:
        return "double-mass" if "K" in set(parameters) else "single-mass"
    return None
