"""Test FMU for the master: a constant source that fails on demand after ``fail_time``."""
import math

from ipcosim.fmus.fmi import FmuBase, StepFailure


class MasterSource(FmuBase):
    """Outputs ``value``; from ``fail_time`` on: 1 discards the step, 2 raises (fatal), 3 outputs NaN."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.add_output("y", unit="m", description="the value", initial_depends_on=("value",))
        self.add_parameter("value", start=1.0, unit="m", description="output value")
        self.add_parameter("fail_time", start=1e9, unit="s", description="time from which to fail")
        self.add_parameter("fail_mode", start=0, type_=int, description="0 never, 1 discard, 2 fatal, 3 NaN")

    def setup(self):
        self.y = self.value

    def step(self, t, h):
        if t + h > self.fail_time + 1e-12 and self.fail_mode:
            if self.fail_mode == 1:
                raise StepFailure(f"source cannot step from t = {t:g} s")
            if self.fail_mode == 2:
                raise RuntimeError(f"source exploded at t = {t:g} s")
            self.y = math.nan
            return
        self.y = self.value
