"""FMU ``MyControllerSingleMass``: my pole-placement state feedback with a Kalman filter (IP02 single-mass cart).

Its whole run-time code is ``my_law.py`` plus the gains design.py writes: Python standard library only.
"""
from my_law import MyController


class MyControllerSingleMass(MyController):
    """Pole-placement state feedback on a Kalman-filter estimate (single-mass cart); output the motor voltage."""

    GAINS = "gains_single_mass.json"
    MEASURED = ("cart_position", "pendulum_angle")
