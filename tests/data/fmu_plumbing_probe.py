"""A small FMU exercising ipcosim.fmus.fmi: feed-through and integrating outputs, an integer output,
checked and tunable parameters, step failures and exceptions on demand."""
import math

from ipcosim.fmus.fmi import FmuBase, StepFailure, positive


class PlumbingProbe(FmuBase):
    """Integrates its input; fails on demand (test FMU for ipcosim.fmus.fmi)."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.add_input("u", start=0.0, unit="V", description="integrand")
        self.add_output("y", unit="V.s", description="integral of gain*u", initial_depends_on=("y0",))
        self.add_output("u_copy", unit="V", description="u (direct feed-through)", depends_on=("u",),
                        initial_depends_on=("u",))
        self.add_output("steps", type_=int, start=0, description="number of steps done", initial_depends_on=())
        self.add_parameter("y0", start=0.0, unit="V.s", description="initial value of y")
        self.add_parameter("gain", start=1.0, unit="1", description="integrator gain", check=positive)
        self.add_parameter("offset", start=0.0, unit="V", description="added to u", tunable=True)
        self.add_parameter("fail_mode", start=0, type_=int,
                           description="0 ok, 1 exception in setup, 2 bug in step")
        self.changes = 0

    def setup(self):
        if self.fail_mode == 1:
            raise RuntimeError("setup exploded")
        self.y = self.y0
        self.u_copy = self.u

    def parameters_changed(self):
        self.changes += 1

    def step(self, t, h):
        if self.fail_mode == 2:
            return [][1]  # a bug: IndexError
        y = self.y + self.gain * (self.u + self.offset) * h
        if not math.isfinite(y):
            raise StepFailure(f"y became {y} in the step from t = {t} s (u = {self.u})")
        self.y = y
        self.u_copy = self.u
        self.steps += 1
