"""Test FMU for the master: a gain with direct feed-through, and a lag without it."""
from ipcosim.fmus.fmi import FmuBase


class MasterGain(FmuBase):
    """y = gain * u (direct feed-through); z integrates aux (no feed-through)."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.add_input("u", start=0.0, unit="m", description="input")
        self.add_input("aux", start=0.0, unit="rad", description="integrated input")
        self.add_output("y", unit="m", description="gain * u", depends_on=("u",), initial_depends_on=("u", "gain"))
        self.add_output("z", unit="rad", description="integral of aux", depends_on=(), initial_depends_on=())
        self.add_parameter("gain", start=2.0, unit="1", description="gain")
        self.add_parameter("sample_period", start=0.01, unit="s", description="steps once per period")

    def setup(self):
        self.y = self.gain * self.u
        self.z = 0.0

    def step(self, t, h):
        self.z = self.z + h * self.aux
        self.y = self.gain * self.u
