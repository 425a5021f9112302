"""My controller's law and FMU class, shared by the two FMU scripts (packed beside each with
``ipcosim.build_fmu(script, files=[..., "my_law.py"])``): Python standard library only.
"""
import json
import math
from pathlib import Path

from ipcosim.fmus.fmi import FmuBase, StepFailure


class ObserverStateFeedback:
    """``u = -K (x^ - x_ref r)`` with ``x^`` from a current-estimator Kalman filter, limited to
    +-voltage_limit.

    Each sample: correct the prediction with the measurement (``x^ = x- + L (y - C x-)``),
    compute the voltage, predict the next state (``x- = Ad x^ + Bd u``) with the voltage
    actually applied.
    """

    def __init__(self, gains: dict, voltage_limit: float) -> None:
        self.Ad, self.Bd, self.C = gains["Ad"], gains["Bd"], gains["C"]
        self.K, self.L = gains["K"], gains["L"]
        self.x_ref = gains["reference_state"]
        self.sample_period = float(gains["sample_period"])
        self.voltage_limit = voltage_limit
        self.x_pred: list[float] | None = None

    def update(self, y: list[float], reference: float) -> float:
        """One sample: measured outputs ``y`` (the ``measured`` list of the gains), reference [m] -> voltage [V]."""
        n = len(self.Ad)
        if self.x_pred is None:  # start from the measured positions, at rest
            self.x_pred = [sum(self.C[i][j] * y[i] for i in range(len(y))) for j in range(n)]
        x = self.x_pred
        innovation = [y[i] - sum(self.C[i][j] * x[j] for j in range(n)) for i in range(len(y))]
        x = [x[j] + sum(self.L[j][i] * innovation[i] for i in range(len(y))) for j in range(n)]
        u = -sum(self.K[j] * (x[j] - self.x_ref[j] * reference) for j in range(n))
        if not math.isfinite(u):
            raise ArithmeticError(f"voltage became {u}")
        u = max(-self.voltage_limit, min(self.voltage_limit, u))
        self.x_pred = [sum(self.Ad[j][k] * x[k] for k in range(n)) + self.Bd[j] * u for j in range(n)]
        return u


def load_gains(path: Path) -> dict:
    """The gains file written by ``design.py``."""
    return json.loads(Path(path).read_text())


class MyController(FmuBase):
    """Pole-placement state feedback on a Kalman-filter estimate; output the motor voltage.

    A plant's FMU script subclasses it and names its gains file and measured outputs.
    """

    GAINS = ""                          # the gains file in the FMU's resources/ (design.py writes it)
    MEASURED: tuple[str, ...] = ()      # the plant's measured outputs, in the gains' order

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.add_input("reference", unit="m", description="reference position of the motor-driven cart")
        for name in self.MEASURED:
            self.add_input(name, unit="rad" if name == "pendulum_angle" else "m", description=f"measured {name}")
        self.add_output("voltage", unit="V", variability="discrete", depends_on=("reference", *self.MEASURED),
                        description="motor voltage command, held over the sample period")
        self.add_parameter("voltage_limit", start=10.0, unit="V", description="output limit",
                           check=lambda v: None if v > 0 else "must be > 0")
        self.law = None

    def setup(self):
        self.law = ObserverStateFeedback(load_gains(Path(self.resources) / self.GAINS), self.voltage_limit)
        self.tick = 0
        self.voltage = self.sample()

    def sample(self):
        return self.law.update([getattr(self, name) for name in self.MEASURED], self.reference)

    def step(self, t, h):
        T = self.law.sample_period
        if h > T * (1 + 1e-6):
            raise StepFailure(f"the communication step {h:g} s is longer than the sample period {T:g} s")
        ticks = (t + h - self.start_time) / T
        k = round(ticks)
        if abs(ticks - k) <= 1e-6 and k > self.tick:  # a sample instant
            try:
                self.voltage = self.sample()
            except ArithmeticError as exc:
                raise StepFailure(f"at t = {t + h:g} s: {exc}") from None
            self.tick = k
