"""Model exchange of the native plants: the hybrid plant of ``ipcosim.fmus.hybrid``, traced.

A native plant FMU offers ``<ModelExchange>`` beside ``<CoSimulation>`` (``c/fmi2me.h``,
``c/fmi3me.h``). Its continuous states are the physical state (``state.<name>``, in
``physics.state_names`` order: the variables the co-simulation step already keeps after each step),
their derivatives ``der(state.<name>)``, and two event indicators per cart (``event.<cart>_motion``,
``event.<cart>_end_stop``: ``hybrid.cart_indicators``). Each cart's mode (``hybrid``: sliding either
way, or at rest) is a discrete state kept in the value array. Two traced functions serve the glue:

* ``model_me_evaluate(v, time)``: the derivatives (``hybrid.derivatives`` for the DAC's code of the
  voltage), the event indicators and the outputs (the encoders' readings of the state) of the value
  array's state and modes;
* ``model_me_update(v, time)``: one pass of the event iteration: the taps (a time event at
  ``tap_time``), the end stops and the carts' modes (``hybrid.settle``), and the next time event.

What model exchange does not model is refused by the FMU on leaving initialization mode:
``input_delay`` (a transport delay is no ordinary differential equation).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from ipcosim.fmus.hybrid import UNKNOWN
from ipcosim.harness.native import tracer
from ipcosim.harness.native.tracer import leaf

#: The plant's state variables (the continuous states of model exchange) and their derivatives.
STATE_PREFIX = "state."
#: The event indicators' variables (``event.<cart>_motion``, ``event.<cart>_end_stop``).
INDICATOR_PREFIX = "event."
#: Slot keys of the carts' modes (start: ``hybrid.UNKNOWN``) and of the next time event (-1: none).
MODE = "S:mode{}"
NEXT_EVENT = "S:next_event"
#: Plant parameters that must stay 0 in model exchange (what it does not model).
EXCHANGE_OFF = ("input_delay",)


def state_key(name: str) -> str:
    """The slot key of the state variable ``name`` (``physics.state_names``)."""
    return f"V:{STATE_PREFIX}{name}"


def discrete_starts(kind: str) -> dict[str, float]:
    """Start values of the slots model exchange adds to plant ``kind``: the carts' modes (unknown until the
    first event) and the next time event (none)."""
    return {MODE.format(k): UNKNOWN for k in range(len(cart_names(kind)))} | {NEXT_EVENT: -1.0}


def derivative_name(name: str) -> str:
    """The variable holding the derivative of state ``name`` (FMI's structured ``der(...)``)."""
    return f"der({STATE_PREFIX}{name})"


def cart_names(kind: str) -> list[str]:
    """The carts' names (``plant.CARTS`` order): ``cart``; ``active_cart``, ``passive_cart``."""
    from ipcosim.fmus.physics import state_names
    from ipcosim.fmus.plant import CARTS

    return [state_names(kind)[ip].removesuffix("_position") for ip, _ in CARTS[kind]]


def indicator_names(kind: str) -> list[str]:
    """The event indicators' variables, two per cart (``hybrid.indicators`` order)."""
    return [f"{INDICATOR_PREFIX}{cart}_{what}" for cart in cart_names(kind) for what in ("motion", "end_stop")]


@dataclass
class Exchange:
    """What the C generator adds to a plant for model exchange: the slot keys of the states, derivatives,
    event indicators and discrete states, and the two traced functions' assignments."""

    states: list[str]
    derivatives: list[str]
    indicators: list[str]
    discrete: list[str]
    evaluate: list[tuple[str, Any]] = field(default_factory=list)
    update: list[tuple[str, Any]] = field(default_factory=list)
    off: list[str] = field(default_factory=list)


def variables(kind: str) -> list[Any]:
    """The model-exchange variables of plant ``kind``: states, their derivatives, the event indicators
    (locals; value references are given by ``models._append``)."""
    from ipcosim.fmus.physics import STATE_UNITS, state_names
    from ipcosim.harness.native.variable import NativeVariable

    out = []
    for s in state_names(kind):
        unit = STATE_UNITS[s]
        out.append(NativeVariable(f"{STATE_PREFIX}{s}", 0, "local", "continuous", initial="calculated", unit=unit,
                                  description=f"{s.replace('_', ' ')}: continuous state (the plant's state "
                                              "after each co-simulation step)"))
    for s in state_names(kind):
        out.append(NativeVariable(derivative_name(s), 0, "local", "continuous", initial="calculated",
                                  unit=_per_second(STATE_UNITS[s]), description=f"derivative of {s}"))
    for name in indicator_names(kind):
        what = "motion" if name.endswith("_motion") else "end stop"
        out.append(NativeVariable(name, 0, "local", "continuous", initial="calculated", unit="1",
                                  description=f"event indicator ({what}, ipcosim.fmus.hybrid.cart_indicators)"))
    return out


def _per_second(unit: str) -> str:
    return {"m": "m/s", "m/s": "m/s2", "rad": "rad/s", "rad/s": "rad/s2", "A": "A/s"}[unit]


def exchange(kind: str, plant: Any) -> Exchange:
    """The traced model exchange of plant ``kind`` (``plant``: the model's ``models._PlantTrace``)."""
    from ipcosim.fmus.physics import state_names
    from ipcosim.harness.native.variable import TAPPED

    names = state_names(kind)
    carts = len(cart_names(kind))
    modes = [MODE.format(k) for k in range(carts)]
    with tracer.math_hooks(), _local_hybrid():
        evaluate = tracer.trace(lambda: _evaluate(kind, plant, modes))
        update = tracer.trace(lambda: _update(kind, plant, modes))
    states = [state_key(s) for s in names]
    ders = [f"V:{derivative_name(s)}" for s in names]
    events = [f"V:{z}" for z in indicator_names(kind)]
    n, nz = len(names), len(events)
    return Exchange(
        states=states, derivatives=ders, indicators=events, discrete=modes + [TAPPED],
        evaluate=list(zip(ders, evaluate[:n])) + list(zip(events, evaluate[n:n + nz]))
        + [(f"V:{s}", v) for s, v in zip(names, evaluate[n + nz:])],
        update=list(zip(states, update[:n])) + list(zip(modes, update[n:n + carts]))
        + [(TAPPED, update[-2]), (NEXT_EVENT, update[-1])],
        off=list(EXCHANGE_OFF))


def _evaluate(kind: str, plant: Any, modes: list[str]) -> list[Any]:
    """Derivatives, event indicators, then the outputs, of the value array's state and modes."""
    from ipcosim.fmus import hybrid

    p = plant.params()
    x = [leaf(state_key(s)) for s in plant.states]
    m = [leaf(k) for k in modes]
    v = plant.quantize(leaf("V:voltage"), leaf("V:voltage_resolution"))
    d = tracer.local(lambda *a: hybrid.derivatives(a[:len(x)], a[len(x)], p, a[len(x) + 1:]))(*x, v, *m)
    z = tracer.local(lambda *a: hybrid.indicators(a[:len(x)], p, a[len(x):-1], a[-1]))(*x, *m, leaf("V:end_stop"))
    return [*d, *z, *plant.outputs(x)]


def _update(kind: str, plant: Any, modes: list[str]) -> list[Any]:
    """One pass of the event iteration: the state and modes after it, the tapped flag, the next time event."""
    from ipcosim.fmus import hybrid
    from ipcosim.fmus.plant import tapped_state
    from ipcosim.harness.native.variable import TAPPED

    p = plant.params()
    x = [leaf(state_key(s)) for s in plant.states]
    force, torque = leaf("V:tap_force_impulse"), leaf("V:tap_torque_impulse")
    armed = tracer.select(leaf(TAPPED) < 0.5, force * force + torque * torque > 0.0, False)
    due = tracer.select(armed, leaf("S:time") >= leaf("V:tap_time"), False)
    x = [tracer.select(due, a, b) for a, b in zip(tapped_state(kind, x, p, force, torque), x)]
    n = len(x)
    settled = tracer.local(lambda *a: [*sum(map(list, hybrid.settle(a[:n], p, a[n:-1], a[-1])), [])])(
        *x, *[leaf(k) for k in modes], leaf("V:end_stop"))
    next_event = tracer.select(tracer.select(armed, leaf("S:time") < leaf("V:tap_time"), False),
                               leaf("V:tap_time"), -1.0)
    return [*settled, tracer.select(due, 1.0, leaf(TAPPED)), next_event]


class _local_hybrid:
    """While tracing: the per-cart helpers of ``ipcosim.fmus.hybrid`` and the voltage clip merged where
    they return (``tracer.local``), so a plant's two carts do not multiply each other's branch paths."""

    NAMES = ("stop_side", "holds", "cart_force", "cart_indicators", "clamp_cart", "settle_cart")

    def __enter__(self) -> None:
        from ipcosim.fmus import hybrid, physics

        self.saved = [(hybrid, n, getattr(hybrid, n)) for n in self.NAMES] + [
            (physics, "clip_voltage", physics.clip_voltage)]
        for module, name, fn in self.saved:
            setattr(module, name, tracer.local(fn))

    def __exit__(self, *exc: Any) -> None:
        for module, name, fn in self.saved:
            setattr(module, name, fn)
