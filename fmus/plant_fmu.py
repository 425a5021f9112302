"""FMI face of the IP02 plants, shared by ``fmu_ip02_single_mass.py`` and ``fmu_ip02_double_mass.py``.

Variables (contract in DESIGN.md): input ``voltage`` [V]; outputs = the full state, the
encoder-measured positions first (``ipcosim.fmus.physics.MEASURED``), then the velocities and
``motor_current``; parameters ``initial_<state>`` and every physical constant of
``ipcosim.fmus.params`` under its own name, unit and description (defaults = the plant's default
thesis preset; the long-pendulum preset ``thesis-appendix-a`` is ``Lp = 0.6413``).

No output depends directly on ``voltage`` (the voltage acts through the integrated
dynamics), so the model structure declares no feed-through and a master sees no
algebraic loop. At initialization each output equals its ``initial_*`` parameter.
"""
from __future__ import annotations

from typing import Any, Sequence

from ipcosim.fmus.fmi import FmuBase, StepFailure
from ipcosim.fmus.params import DEFAULT_PRESET, PLANT_KINDS, PRESETS, make, parameter_info
from ipcosim.fmus.physics import MEASURED, STATE_UNITS, state_names
from ipcosim.fmus.plant import Plant, PlantStepError

_STATE_DOC = {
    "cart_position": "cart position (encoder), positive to the right",
    "cart_velocity": "cart velocity",
    "active_cart_position": "position of the motor-driven (active) cart (encoder)",
    "active_cart_velocity": "velocity of the active cart",
    "passive_cart_position": "position of the passive cart carrying the pendulum (encoder)",
    "passive_cart_velocity": "velocity of the passive cart",
    "pendulum_angle": "pendulum angle from upright, counter-clockwise positive (encoder)",
    "pendulum_velocity": "pendulum angular velocity",
    "motor_current": "armature current of the DC motor",
}


class PlantFmu(FmuBase):
    """Nonlinear IP02 plant advanced by ``ipcosim.fmus.plant.Plant`` (ETDRK4), voltage held over each step."""

    #: 'single-mass' or 'double-mass' (set by the FMU classes).
    kind: str = ""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        kind = self.kind
        names = state_names(kind)
        self._names = names
        self._x = [0.0] * len(names)
        self.plant: Plant | None = None
        defaults = dict(PRESETS[DEFAULT_PRESET[kind]][1])
        self.add_input("voltage", start=0.0, unit="V",
                       description="amplifier command to the motor (clipped to +-voltage_limit)")
        order = list(MEASURED[kind]) + [n for n in names if n not in MEASURED[kind]]
        #: value reference of each output -> its index in the state (fast path of get_real)
        self._state_index: dict[int, int] = {}
        for name in order:
            k = names.index(name)
            info = self.add_output(name, unit=STATE_UNITS[name], description=_STATE_DOC[name],
                                   getter=(lambda k=k: self._x[k]), depends_on=(),
                                   initial_depends_on=(f"initial_{name}",))
            self._state_index[info.value_reference] = k
        for name in names:
            self.add_parameter(f"initial_{name}", start=0.0, unit=STATE_UNITS[name],
                               description=f"initial {_STATE_DOC[name].split(' (')[0]}")
        self._param_names: list[str] = []
        for info in parameter_info(PLANT_KINDS[kind]):
            self._param_names.append(info["name"])
            self.add_parameter(info["name"], start=defaults.get(info["name"], info["default"]), unit=info["unit"],
                               description=f"{info['doc']} [{info['source']}]")

    def get_real(self, vrs: Sequence[int]) -> list[float]:
        # the master's per-step read of the outputs: straight from the state list
        x, index = self._x, self._state_index
        try:
            return [x[index[vr]] for vr in vrs]
        except KeyError:
            return super().get_real(vrs)

    def setup(self) -> None:
        # params.make validates: "parameter Mp = -1.0 kg must be > 0 (pendulum mass)" (ParameterError)
        params = make(self.kind, **{n: getattr(self, n) for n in self._param_names})
        x0 = [getattr(self, f"initial_{n}") for n in self._names]
        self.plant = Plant(params, x0, t0=self.start_time)
        self._x = self.plant.state

    def step(self, t: float, h: float) -> None:
        plant = self.plant
        try:
            plant.do_step(t, h, self.voltage)
        except (PlantStepError, ValueError) as exc:
            raise StepFailure(str(exc)) from exc
        self._x = plant._xl  # the plant replaces (never mutates) this list on each step
