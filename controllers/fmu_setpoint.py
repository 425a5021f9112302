"""FMU ``Setpoint``: the reference position of the motor-driven cart (step, ramp or square wave)."""
from __future__ import annotations

from typing import Any

from ipcosim.controllers.errors import ControllerParameterError
from ipcosim.controllers.reference import check_reference, reference_at
from ipcosim.fmus.fmi import FmuBase, FmuError


class Setpoint(FmuBase):
    """Reference position of the motor-driven cart: step (default 0 -> 0.05 m at t = 0), ramp or square wave."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.add_output("reference", start=0.0, unit="m", description="reference position of the motor-driven cart",
                        depends_on=(), initial_depends_on=("waveform", "amplitude", "step_time", "offset",
                                                           "ramp_rate", "period"))
        self.add_parameter("waveform", start=0, type_=int,
                           description="0 = step, 1 = ramp (towards offset + amplitude at ramp_rate), "
                                       "2 = square wave (offset + amplitude for the first half of each period)")
        self.add_parameter("amplitude", start=0.05, unit="m", description="size of the step / ramp / square wave")
        self.add_parameter("step_time", start=0.0, unit="s", description="time the step, ramp or square wave starts")
        self.add_parameter("offset", start=0.0, unit="m", description="reference before step_time")
        self.add_parameter("ramp_rate", start=0.05, unit="m/s", description="ramp speed (waveform 1)")
        self.add_parameter("period", start=4.0, unit="s", description="square-wave period (waveform 2)")

    def _value(self, t: float) -> float:
        return reference_at(t, int(self.waveform), self.amplitude, self.step_time, self.offset, self.ramp_rate,
                            self.period)

    def setup(self) -> None:
        try:
            check_reference(int(self.waveform), self.amplitude, self.step_time, self.offset, self.ramp_rate,
                            self.period)
        except ControllerParameterError as exc:
            raise FmuError(f"Setpoint: {exc}") from None
        self.reference = self._value(self.start_time)

    def step(self, t: float, h: float) -> None:
        self.reference = self._value(t + h)
