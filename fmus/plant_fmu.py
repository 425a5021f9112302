"""FMI face of the IP02 plants, shared by ``fmu_ip02_single_mass.py`` and ``fmu_ip02_double_mass.py``.

Variables (docs/plant.md, The plant FMUs): input ``voltage`` [V]; outputs = the full state, the
encoder-measured positions first (``ipcosim.fmus.physics.MEASURED``), then the velocities and
``motor_current``; parameters ``initial_<state>`` and every physical constant of
``ipcosim.fmus.params`` under its own name, unit and description (defaults = the plant's default
thesis preset; the long-pendulum preset ``thesis-appendix-a`` is ``Lp = 0.6413``).

No output depends directly on ``voltage`` (the voltage acts through the integrated
dynamics), so the model structure declares no feed-through and a master sees no
algebraic loop. At initialization each output equals its ``initial_*`` parameter.

The measured positions are what the encoders read (``ipcosim.fmus.instruments``): exact by
default; whole counts with ``cart_resolution`` / ``pendulum_resolution``, plus seeded noise with
``noise_counts``; ``end_stop`` stops the carts at the ends of the track; ``voltage_resolution`` and
``input_delay`` are the DAC's codes and the computation delay of the voltage.
"""
from __future__ import annotations

from typing import Any, Sequence

from ipcosim.fmus.fmi import FmuBase, StepFailure
from ipcosim.fmus.instruments import InstrumentError, Instruments
from ipcosim.fmus.params import DEFAULT_PRESET, PLANT_KINDS, PRESETS, ParameterError, make, parameter_info
from ipcosim.fmus.physics import MEASURED, STATE_UNITS, state_names
from ipcosim.fmus.plant import InstrumentedPlant, PlantStepError

#: Instrument options (``ipcosim.fmus.instruments.Instruments``) as FMU parameters; 0 = off.
_INSTRUMENT_DOC = (
    ("cart_resolution", "m", "cart encoder resolution: position outputs are whole counts of it; 0 = exact "
                             "(IP02: 2.275e-5)"),
    ("pendulum_resolution", "rad", "pendulum encoder resolution: the angle output is whole counts of it; 0 = exact "
                                   "(IP02: 1.534e-3)"),
    ("noise_counts", "1", "standard deviation of Gaussian noise on the measured outputs, in counts; 0 = none"),
    ("noise_seed", "1", "seed of the measurement noise (the same seed gives the same run)"),
    ("end_stop", "m", "track end stops at +-end_stop for every cart (IP02: 0.407); 0 = none"),
    ("input_delay", "s", "transport delay of the voltage (a computation delay), whole plant steps; 0 = none"),
    ("tap_time", "s", "time of the taps"),
    ("tap_force_impulse", "N.s", "impulse of a force tap on the cart carrying the pendulum; 0 = none"),
    ("tap_torque_impulse", "N.m.s", "impulse of a torque tap on the pendulum (counter-clockwise); 0 = none"),
    ("voltage_resolution", "V", "D/A converter resolution: the voltage is a whole number of codes of it; 0 = exact "
                                "(Q4: 20/4096 = 4.883e-3)"),
)

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
        self.plant: InstrumentedPlant | None = None
        defaults = dict(PRESETS[DEFAULT_PRESET[kind]][1])
        self.add_input("voltage", start=0.0, unit="V",
                       description="amplifier command to the motor (clipped to +-voltage_limit)")
        measured = MEASURED[kind]
        order = list(measured) + [n for n in names if n not in measured]
        self._y = [0.0] * len(measured)
        #: value reference of each output -> its index in ``self._out`` (the measured readings, then
        #: the state): the fast path of get_real
        self._out_index: dict[int, int] = {}
        self._out: list[float] = self._y + self._x
        for name in order:
            k = names.index(name)
            j = measured.index(name) if name in measured else -1
            getter = (lambda j=j: self._y[j]) if j >= 0 else (lambda k=k: self._x[k])
            info = self.add_output(name, unit=STATE_UNITS[name], description=_STATE_DOC[name],
                                   getter=getter, depends_on=(), initial_depends_on=(f"initial_{name}",))
            self._out_index[info.value_reference] = j if j >= 0 else len(measured) + k
        for name in names:
            self.add_parameter(f"initial_{name}", start=0.0, unit=STATE_UNITS[name],
                               description=f"initial {_STATE_DOC[name].split(' (')[0]}")
        self._param_names: list[str] = []
        for info in parameter_info(PLANT_KINDS[kind]):
            self._param_names.append(info["name"])
            self.add_parameter(info["name"], start=defaults.get(info["name"], info["default"]), unit=info["unit"],
                               description=f"{info['doc']} [{info['source']}]")
        for name, unit, doc in _INSTRUMENT_DOC:
            self.add_parameter(name, start=0.0, unit=unit, description=doc)

    def get_real(self, vrs: Sequence[int]) -> list[float]:
        # the master's per-step read of the outputs: straight from the readings and the state
        out, index = self._out, self._out_index
        try:
            return [out[index[vr]] for vr in vrs]
        except KeyError:
            return super().get_real(vrs)

    def setup(self) -> None:
        # params.make validates: "parameter Mp = -1.0 kg must be > 0 (pendulum mass)" (ParameterError)
        params = make(self.kind, **{n: getattr(self, n) for n in self._param_names})
        x0 = [getattr(self, f"initial_{n}") for n in self._names]
        try:
            instruments = Instruments(**{n: (int(getattr(self, n)) if n == "noise_seed" else float(getattr(self, n)))
                                         for n, _, _ in _INSTRUMENT_DOC})
        except InstrumentError as exc:
            raise ParameterError(str(exc).replace("instrument option", "parameter")) from None
        self.plant = InstrumentedPlant(params, x0, t0=self.start_time, instruments=instruments)
        self._x = self.plant.state
        self._y = list(self.plant.readings)
        self._out = self._y + self._x

    def step(self, t: float, h: float) -> None:
        plant = self.plant
        try:
            plant.do_step(t, h, self.voltage)
        except (PlantStepError, ValueError) as exc:
            raise StepFailure(str(exc)) from exc
        self._x = plant._xl  # the plant replaces (never mutates) this list on each step
        self._y = list(plant.readings)
        self._out = self._y + self._x
