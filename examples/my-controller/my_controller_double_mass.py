"""FMU ``MyControllerDoubleMass``: my pole-placement state feedback with a Kalman filter (IP02 double-mass cart).

Its whole run-time code is ``my_law.py`` plus the gains design.py writes: Python standard library only.
"""
from my_law import MyController


class MyControllerDoubleMass(MyController):
    """Pole-placement state feedback on a Kalman-filter estimate (double-mass cart); output the motor voltage."""

    GAINS = "gains_double_mass.json"
    MEASURED = ("active_cart_position", "passive_cart_position", "pendulum_angle")
