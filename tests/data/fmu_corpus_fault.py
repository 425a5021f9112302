"""Test FMU for the bad-input corpus: y = u, with a fault chosen by ``fault`` from ``fail_time`` on."""
import math
import time

from ipcosim.fmus.fmi import FmuBase, StepFailure


class CorpusFault(FmuBase):
    """y = u; fault 1 raises (fatal), 2 outputs NaN, 3 discards the step, 4 hangs, 5 sleeps
    ``delay`` seconds every step (a slow FMU, for signals), 6 raises while initializing."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.add_input("u", start=0.0, unit="m", description="input")
        self.add_output("y", unit="m", description="the input", depends_on=("u",), initial_depends_on=("u",))
        self.add_parameter("fault", start=0, type_=int, description="fault kind (see the class docstring)")
        self.add_parameter("fail_time", start=0.0, unit="s", description="time from which to fail")
        self.add_parameter("delay", start=0.0, unit="s", description="wall-clock seconds per step (fault 5)")
        self.add_parameter("init_delay", start=0.0, unit="s", description="wall-clock seconds in initialization")

    def setup(self):
        time.sleep(self.init_delay)
        if self.fault == 6:
            raise RuntimeError("corpus fault: initialization exploded")
        self.y = self.u

    def step(self, t, h):
        if self.fault == 5:
            time.sleep(self.delay)
        elif self.fault and t + h > self.fail_time + 1e-12:
            if self.fault == 1:
                raise RuntimeError(f"corpus fault: exploded at t = {t:g} s")
            if self.fault == 2:
                self.y = math.nan
                return
            if self.fault == 3:
                raise StepFailure(f"corpus fault: cannot step from t = {t:g} s")
            if self.fault == 4:
                while True:
                    time.sleep(0.05)
        self.y = self.u
