"""What the live page draws, from the plant kind: the scene of a run.

The page itself knows no pendulum. It is handed a scene (plain JSON): which columns are the
reference, the cart positions, the pendulum angle and the voltage, the cart that carries the
pendulum and the pendulum's length, the limits to draw (each cart's software limit and the track's
end stops, the pendulum's limit, the voltage limit) and the columns that carry a card's status.
The scene comes from the plant kind (:func:`ipcosim.fmus.kinds.plant_kind`) and the run plot's own
names for the positions (:data:`ipcosim.harness.api.plot.POSITIONS`), so the live view and
``plot.png`` draw the same signals; a scenario of another kind gets its Real columns plotted
and no animation.
"""
from __future__ import annotations

from typing import Any, Callable, Sequence

from ipcosim.fmus import instruments
from ipcosim.fmus.kinds import PENDULUM_CART, plant_kind
from ipcosim.harness.api.plot import POSITIONS

#: Columns that can hold the reference and the voltage, in the order the run plot looks for them.
REFERENCES = ("setpoint.reference", "controller.reference")
VOLTAGES = ("controller.voltage", "plant.voltage")
#: A card's status outputs (the HIL adapter's) shown beside the rig's own status.
STATUS_OUTPUTS = ("watchdog_expired", "limit_tripped", "overruns")
#: Distance at which two carts are drawn apart at rest [m] (a drawing's choice: each measures from its start).
CART_SPACING_M = 0.16
#: Pendulum length drawn when the plant does not say (the IP02's medium pendulum, full length) [m].
DEFAULT_PENDULUM_M = 0.337


def scene(columns: Sequence[str], title: str, start: Callable[[str, str], Any] = lambda c, v: None,
          voltage_limit: float | None = None) -> dict[str, Any]:
    """The scene of a run with these recorded ``columns``.

    Parameters
    ----------
    columns : sequence of str
        ``time``, then ``component.variable``.
    title : str
        The scenario's name (and what else the page's heading says).
    start : callable
        ``start(component, variable)``: the value the run starts with (None when unknown), for
        the pendulum's length and the voltage limit.
    voltage_limit : float, optional
        The voltage limit [V] when known otherwise (a finished run's metadata).

    Returns
    -------
    dict
        ``title``, ``kind``, ``reference``, ``carts`` (``[{"column", "label", "drawn_at_m"}]``), ``pendulum``
        (``{"column", "cart", "length_m"}`` or None), ``voltage``, ``limits``, ``status`` and
        ``others`` (the columns plotted when the kind is unknown).
    """
    cols = set(columns)
    connectors = [c.split(".", 1)[1] for c in columns if c.startswith("plant.")]
    kind = plant_kind(title, connectors=connectors) if connectors else None
    carts = [{"column": c, "label": label} for c, label in POSITIONS if c in cols]
    for k, cart in enumerate(carts):  # each cart's position is from its own start: drawn at a rest spacing
        cart["drawn_at_m"] = (k - (len(carts) - 1) / 2) * CART_SPACING_M
    angle = "plant.pendulum_angle" if "plant.pendulum_angle" in cols else None
    pendulum = None
    if angle and kind in PENDULUM_CART and f"plant.{PENDULUM_CART[kind]}" in cols:
        length = _number(start("plant", "Lp")) or DEFAULT_PENDULUM_M
        pendulum = {"column": angle, "cart": f"plant.{PENDULUM_CART[kind]}", "length_m": length}
    limit_v = voltage_limit or _number(start("controller", "voltage_limit")) or _number(start("plant", "voltage_limit"))
    limits = {"cart_m": instruments.CART_LIMIT_M, "end_stop_m": instruments.END_STOP_M,
              "pendulum_rad": instruments.PENDULUM_LIMIT_RAD,
              "voltage_V": limit_v or instruments.DAC_RANGE_V,
              "voltage_label": "voltage limit" if limit_v else "card range"}
    voltage = next((c for c in VOLTAGES if c in cols), None)
    reference = next((c for c in REFERENCES if c in cols), None)
    shown = {reference, voltage, angle, *(c["column"] for c in carts)}
    others = [] if carts or angle else [c for c in columns[1:] if c not in shown][:8]
    return {"title": title, "kind": kind, "reference": reference, "carts": carts, "pendulum": pendulum,
            "angle": angle, "voltage": voltage, "limits": limits, "others": others,
            "status": {name: f"plant.{name}" for name in STATUS_OUTPUTS if f"plant.{name}" in cols}}


def _number(value: Any) -> float | None:
    """A positive float, or None."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        return None
    return number if number > 0 else None
