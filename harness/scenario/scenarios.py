"""The project's scenarios as data: the plants, the controllers of the plant x controller scenarios and the
variants beyond them (``ssp/<name>/``). The scenarios' files in ``ssp/`` are written from this table
(docs/master.md); the comparison (``ipcosim.harness.studies.compare``) tells the variants, which pose other
tasks, from it."""
from __future__ import annotations

from ipcosim.fmus.kinds import ByKind

#: The plants (``ipcosim.fmus.kinds``): kind -> its plant FMU's model name, model-name suffix and description.
PLANTS = ByKind(lambda k: {"model": k.model, "suffix": k.suffix, "description": k.description})
CONTROLLERS = {
    "pid": ("PID", "the thesis's single-loop PID on the cart position"),
    "cascade-pid": ("CascadePID", "cascade PID: inner loop on the pendulum angle, outer loop on the cart position"),
    "lqr": ("LQR", "LQR state feedback with a Luenberger observer"),
    "hsmc": ("HSMC", "hierarchical sliding-mode control"),
    "adaptive-hsmc": ("AdaptiveHSMC", "hierarchical sliding-mode control with scheduled gains"),
    "lqg": ("LQG", "discrete LQG with integral action and the computation delay (Kalman filter)"),
}
STATE_UNITS = {"cart_position": "m", "cart_velocity": "m/s", "active_cart_position": "m",
               "active_cart_velocity": "m/s", "passive_cart_position": "m", "passive_cart_velocity": "m/s",
               "pendulum_angle": "rad", "pendulum_velocity": "rad/s", "motor_current": "A"}
UNITS = {"m": {"m": 1}, "rad": {"rad": 1}, "V": {"kg": 1, "m": 2, "s": -3, "A": -1}, "A": {"A": 1},
         "m/s": {"m": 1, "s": -1}, "rad/s": {"rad": 1, "s": -1}, "s": {"s": 1}}
STOP_TIME = 10.0
STEP = 1e-3
AMPLITUDE = 0.05
STEP_TIME = 0.0

#: Scenarios beyond the twelve: (plant, law, description, setpoint amplitude [m], stop time [s], plant start values).
#: The lab values are ``ipcosim.fmus.instruments.REALISM["lab"]`` (written out so the files stay literal).
_LAB_DOUBLE = {"b1": 0.1047, "b2": 0.1047, "cart_resolution": 2.275e-05, "pendulum_resolution": 0.0015339807878856412,
               "end_stop": 0.407, "input_delay": 0.001, "voltage_resolution": 0.0048828125}
_LAB_SINGLE = {"b": _LAB_DOUBLE["b1"], **{k: v for k, v in _LAB_DOUBLE.items() if not k.startswith("b")}}
_HANGING = {"initial_pendulum_angle": 3.141592653589793}
_IDENTIFY = ("a multisine voltage (0.2 .. 10 Hz, 3 V peak) with a weak hold of the motor-driven cart at 0, the "
             "pendulum hanging, on the lab plant (encoder counts, stick-slip Coulomb friction, end stops, DAC codes, "
             "one-sample delay): the identification experiment of docs/identify.md")
VARIANTS: dict[str, tuple[str, str, str, float, float, dict[str, float]]] = {
    "single-mass-swing-up": ("single-mass", "SwingUp", "energy swing-up from hanging, hand-over to the thesis's LQR; "
                             "the cart stays at 0", 0.0, 15.0, {"initial_pendulum_angle": 3.141592653589793}),
    "single-mass-lqr-tap": ("single-mass", "LQR", "the thesis's LQR holding the cart at 0; a torque tap of 0.005 N m s "
                            "on the pendulum at t = 2 s", 0.0, 10.0, {"tap_time": 2.0, "tap_torque_impulse": 0.005}),
    "double-mass-hsmc-lab": ("double-mass", "HSMC", "the thesis's HSMC on the lab plant (encoder counts, stick-slip "
                             "Coulomb friction, end stops, DAC codes, one-sample delay); the active cart moves "
                             "0 -> 0.05 m",
                             AMPLITUDE, 20.0, _LAB_DOUBLE),
    "single-mass-identify": ("single-mass", "Excitation", _IDENTIFY, 0.0, 20.0, {**_LAB_SINGLE, **_HANGING}),
    "double-mass-identify": ("double-mass", "Excitation", _IDENTIFY, 0.0, 20.0, {**_LAB_DOUBLE, **_HANGING}),
}


def scenario_names() -> list[str]:
    return [f"{p}-{c}" for p in PLANTS for c in CONTROLLERS] + list(VARIANTS)
