"""FMI face of the control laws, shared by the ``controllers/fmu_<law>_<plant>.py`` scripts.

Variables (docs/controllers.md, FMUs): inputs ``reference`` [m] and the plant's measured positions
(``ipcosim.fmus.physics.MEASURED``); output ``voltage`` [V]; parameters = the law's schema
(``ipcosim.controllers.laws.base.LawEntry.schema``: every gain and weight with its unit; ``sample_period``,
``voltage_limit``; the model-based laws' ``model_*`` design-model constants). The LQR and LQG FMUs also have
the gains as parameters (their entry's ``designed.gain_specs``): ``K_<state>``, ``N`` (LQR) or ``K_voltage``,
``K_integral`` (LQG), and the estimator gain ``M_<state>_<output>``.

Runtime: on its default path an FMU imports only the Python standard library. The laws run on
plain floats (the law's module of ``ipcosim.controllers.laws``, the only one the FMU carries: the script
names its law's registry entry); the HSMC laws' design model is a plain-Python
linearization. The LQR's and LQG's gains for the parameter values an FMU ships with are designed when the
FMU is built and stored in it (``shipped_<Model>.json`` in its private package, start values of
the gain parameters). On leaving initialization mode:

* no design parameter changed (``LawEntry.design_parameters``: weights, observer poles, noises,
  ``model_*``, ``sample_period``) -> the gain parameters as set (the shipped ones, or the user's);
* a design parameter changed and no gain was set -> the gains are redesigned with the ``scipy``
  back end, importing numpy and scipy only then; if they are missing, initialization fails
  with one line naming the parameter and saying that the gains can be set instead; after
  initialization the gain parameters read the gains in effect;
* gains set and ``model_*`` or ``sample_period`` changed -> the given gains, with the
  zero-order-hold model recomputed in plain Python; gains set together with a changed weight or
  observer pole -> an error naming both (the two ways of fixing the gains contradict each other).

The output at the start time is computed from the inputs set during initialization (outputs
correct at t = 0). A bad parameter ends there with fmi2Fatal and a message naming it
(``ipcosim.fmus.fmi``).

Sampling: the output is updated once per sample instant ``t0 + k sample_period`` (k counted as an
integer from the master's times), from the inputs current at that instant -- the inputs set just
before the ``fmi2DoStep`` that ends at the instant -- and held in between. The model structure
declares the output as depending directly on every input (sampled without delay), so a
Gauss-Seidel master steps setpoint, plant, controller. A communication step longer than the
sample period, or one that skips a sample instant, fails with fmi2Discard.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from ipcosim.controllers.errors import ControllerParameterError
from ipcosim.controllers.laws.base import DiscreteLaw, LawEntry, LawInputError
from ipcosim.fmus.fmi import FmuBase, FmuError, StepFailure
from ipcosim.fmus.physics import MEASURED, STATE_UNITS

_INPUT_DOC = {
    "cart_position": "measured cart position (encoder)",
    "active_cart_position": "measured position of the motor-driven (active) cart (encoder)",
    "passive_cart_position": "measured position of the passive cart carrying the pendulum (encoder)",
    "pendulum_angle": "measured pendulum angle from upright, counter-clockwise positive (encoder)",
}
#: Shipped designs read (or designed) in this process, by file name (the FMU class is re-created
#: on every instantiation by pythonfmu's wrapper; this module is not).
_SHIPPED: dict[str, dict[str, Any]] = {}
#: Slack when deciding whether the end of a step is a sample instant, in sample periods.
TICK_TOLERANCE = 1e-6


class ControllerFmu(FmuBase):
    """A discrete control law sampled at ``sample_period`` (``ipcosim.controllers.laws``)."""

    #: The law's registry entry (its module's ``LawEntry``) and the plant kind, set by the FMU classes.
    law: LawEntry
    kind: str = ""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        kind = self.kind
        self._measured = MEASURED[kind]
        self._controller: DiscreteLaw | None = None
        self._specs = self.law.schema(kind)
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
        self._gain_specs = self.law.designed.gain_specs(kind) if self.law.designed else []
        if self._gain_specs:
            shipped = type(self).shipped_design(self.resources)["gains"]
            for spec in self._gain_specs:
                self.add_parameter(spec.name, start=shipped[spec.name], unit=spec.unit,
                                   description=f"{spec.description}; designed at build time for the default "
                                               "parameters, redesigned at initialization when a design "
                                               "parameter changes (then it reads the gain in effect)")

    # --- the design stored in the FMU --------------------------------------------------------------

    @classmethod
    def shipped_name(cls) -> str:
        """File name of the shipped design inside the FMU's private package."""
        return f"shipped_{cls.law.model_name(cls.kind)}.json"

    @classmethod
    def shipped_design(cls, resources: str | None = None) -> dict[str, Any]:
        """``{"design": {parameter: value}, "gains": {gain: value}}`` for the default parameters.

        Read from the private package in the FMU's ``resources`` folder; elsewhere (the source tree)
        designed now with the design stack. Once per process and model.
        """
        name = cls.shipped_name()
        record = _SHIPPED.get(name)
        if record is None:
            package = __name__.split(".", 1)[0]
            candidates = [Path(__file__).resolve().parents[1] / name]
            if resources:
                candidates.insert(0, Path(resources) / package / name)
            path = next((c for c in candidates if c.is_file()), None)
            record = _SHIPPED[name] = json.loads(path.read_text()) if path else cls.design_record()
        return record

    @classmethod
    def design_record(cls) -> dict[str, Any]:
        """Design the gains for the default parameters (imports numpy and scipy): the shipped design."""
        entry = cls.law
        assert entry.designed is not None
        values = entry.defaults(cls.kind)
        law = entry.make(cls.kind, values, backend="scipy")
        design = {name: values[name] for name in entry.design_parameters(cls.kind)}
        return {"model": entry.model_name(cls.kind), "design": design, "gains": entry.designed.gains(law)}

    @classmethod
    def build_files(cls) -> dict[str, str]:
        """Files the build adds to the FMU's private package: the shipped design of a designed law."""
        if cls.law.designed is None:
            return {}
        return {cls.shipped_name(): json.dumps(cls.design_record(), indent=1, sort_keys=True)}

    # --- initialization ----------------------------------------------------------------------------

    def _build_law(self) -> DiscreteLaw:
        entry, kind = self.law, self.kind
        values = {s.name: getattr(self, s.name) for s in self._specs}
        name = entry.model_name(kind)
        if entry.designed is None:
            return entry.make(kind, values)
        shipped = type(self).shipped_design(self.resources)
        gains = {s.name: float(getattr(self, s.name)) for s in self._gain_specs}
        changed = [n for n in entry.design_parameters(kind) if float(values[n]) != shipped["design"][n]]
        set_gains = [n for n, v in gains.items() if v != shipped["gains"][n]]
        weights = [n for n in changed if n in entry.designed.weight_parameters(kind)]
        if set_gains and weights:
            raise FmuError(f"{name}: parameters {weights[0]} and {set_gains[0]} were both set: give either the "
                           "design (weights, observer poles) or the gains K_*, N, M_*, not both")
        if not changed or set_gains:
            return entry.designed.from_gains(kind, values, gains)
        try:
            law = entry.make(kind, values, backend="scipy")
        except ImportError as exc:
            raise FmuError(f"{name}: parameter {changed[0]} = {values[changed[0]]:g} differs from the shipped "
                           f"design, and redesigning the gains needs numpy and scipy ({exc}); install them in "
                           "this Python, or keep the design parameters and set the gains K_*, N, M_* instead") from None
        for gain, value in entry.designed.gains(law).items():
            setattr(self, gain, value)
        return law

    def setup(self) -> None:
        try:
            law = self._build_law()
        except ControllerParameterError as exc:
            raise FmuError(f"{self.law.model_name(self.kind)}: {exc}") from None
        self._controller = law
        self._tick = 0
        self.voltage = self._sample()

    def _sample(self) -> float:
        law = self._controller
        assert law is not None
        try:
            return float(law.step([getattr(self, n) for n in self._measured], self.reference))
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
