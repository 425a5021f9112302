"""FMI face of the control laws, shared by the ``controllers/fmu_<law>_<plant>.py`` scripts.

Variables (DESIGN.md contract): inputs ``reference`` [m] and the plant's measured positions
(``ipcosim.fmus.physics.MEASURED``); output ``voltage`` [V]; parameters = ``ipcosim.controllers.catalog.schema``
(every gain and weight with its unit; ``sample_period``, ``voltage_limit``; the model-based laws'
``model_*`` design-model constants). The LQR FMUs also publish the gains their weights imply as
calculated parameters ``K_<state>`` and ``N``.

Initialization: on leaving initialization mode the law is built from the parameters by
``ipcosim.controllers.catalog.build_law`` -- the LQR redone with the ``scipy`` back end, so a changed
weight gives the gains it implies -- and the output at the start time is computed from the
inputs set during initialization (outputs correct at t = 0). A bad parameter ends there with
fmi2Fatal and a message naming it (``ipcosim.fmus.fmi``).

Sampling: the output is updated once per sample instant ``t0 + k sample_period`` (k counted as an
integer from the master's times), from the inputs current at that instant -- the inputs set just
before the ``fmi2DoStep`` that ends at the instant -- and held in between. The model structure
declares the output as depending directly on every input (sampled without delay), so a
Gauss-Seidel master steps setpoint, plant, controller. A communication step longer than the
sample period, or one that skips a sample instant, fails with fmi2Discard.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ipcosim.controllers.catalog import model_name, schema
from ipcosim.controllers.errors import ControllerParameterError
from ipcosim.controllers.laws import LQR, DiscreteLaw, LawInputError
from ipcosim.fmus.fmi import FmuBase, FmuError, StepFailure
from ipcosim.fmus.physics import MEASURED, STATE_UNITS

_INPUT_DOC = {
    "cart_position": "measured cart position (encoder)",
    "active_cart_position": "measured position of the motor-driven (active) cart (encoder)",
    "passive_cart_position": "measured position of the passive cart carrying the pendulum (encoder)",
    "pendulum_angle": "measured pendulum angle from upright, counter-clockwise positive (encoder)",
}
#: Slack when deciding whether the end of a step is a sample instant, in sample periods.
TICK_TOLERANCE = 1e-6


class ControllerFmu(FmuBase):
    """A discrete control law sampled at ``sample_period`` (``ipcosim.controllers.laws``)."""

    #: Law name (``ipcosim.controllers.catalog.LAWS``) and plant kind, set by the FMU classes.
    law: str = ""
    kind: str = ""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        kind = self.kind
        self._measured = MEASURED[kind]
        self._controller: DiscreteLaw | None = None
        self._specs = schema(self.law, kind)
        self.add_input("reference", start=0.0, unit="m",
                       description="reference position of the motor-driven cart")
        for name in self._measured:
            self.add_input(name, start=0.0, unit=STATE_UNITS[name], description=_INPUT_DOC[name])
        self.add_output("voltage", start=0.0, unit="V", variability="discrete",
                        description="motor voltage command, held over the sample period, limited to "
                                    "+-voltage_limit",
                        depends_on=("reference", *self._measured))
        for spec in self._specs:
            is_bool = spec.constraint == "bool"
            self.add_parameter(spec.name, start=bool(spec.default) if is_bool else float(spec.default),
                               type_=bool if is_bool else float, unit=None if is_bool else spec.unit,
                               description=spec.description, check=None if is_bool else spec.check)
        self._gains: dict[str, float] = {}
        if self.law == "LQR":
            from ipcosim.controllers.catalog import design_states  # noqa: PLC0415
            for state in design_states(kind):
                name = f"K_{state}"
                unit = "V/" + STATE_UNITS[state]
                if "/" in STATE_UNITS[state]:
                    num, den = STATE_UNITS[state].split("/")
                    unit = f"V.{den}/{num}"
                self._gains[name] = 0.0
                self.add_variable(name, "calculatedParameter", unit=unit,
                                  description=f"LQR gain on the estimated {state} (u = -K x^ + N r), computed "
                                              "from the weights at initialization",
                                  getter=(lambda n=name: self._gains[n]))
            self._gains["N"] = 0.0
            self.add_variable("N", "calculatedParameter", unit="V/m",
                              description="reference gain N = -1/(C1 (A - B K)^-1 B), computed at initialization",
                              getter=(lambda: self._gains["N"]))

    def setup(self) -> None:
        from ipcosim.controllers.catalog import build_law  # noqa: PLC0415

        values = {s.name: getattr(self, s.name) for s in self._specs}
        try:
            law = build_law(self.law, self.kind, values, backend="scipy")
        except ControllerParameterError as exc:
            raise FmuError(f"{model_name(self.law, self.kind)}: {exc}") from None
        self._controller = law
        if isinstance(law, LQR):
            d = law.design
            for i, state in enumerate(d.model.states):
                self._gains[f"K_{state}"] = float(d.K[0, i])
            self._gains["N"] = float(d.N)
        self._tick = 0
        self.voltage = self._sample()

    def _sample(self) -> float:
        law = self._controller
        assert law is not None
        y = np.array([getattr(self, n) for n in self._measured], dtype=float)
        try:
            return float(law.step(y, float(self.reference)))
        except LawInputError as exc:
            raise StepFailure(str(exc)) from None

    def step(self, t: float, h: float) -> None:
        law = self._controller
        assert law is not None
        T = law.sample_period
        if h > T * (1 + TICK_TOLERANCE):
            raise StepFailure(f"communication step h = {h:g} s is longer than sample_period = {T:g} s: the "
                              "controller would miss sample instants (use a master step that divides sample_period)")
        ticks = (t + h - self.start_time) / T
        k = round(ticks)
        if abs(ticks - k) <= TICK_TOLERANCE and k > self._tick:
            if k != self._tick + 1:
                raise StepFailure(f"sample instant {self._tick + 1} (t = {self.start_time + (self._tick + 1) * T:g} s) "
                                  f"was skipped by the step from t = {t:g} s")
            self.voltage = self._sample()
            self._tick = k
