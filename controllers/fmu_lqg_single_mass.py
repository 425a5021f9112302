"""FMU ``LQGSingleMass``: discrete LQG with integral action and a one-sample computation delay (discrete
LQR on the sampled plant, steady-state Kalman filter), for the IP02 single-mass cart."""
from ipcosim.controllers.controller_fmu import ControllerFmu
from ipcosim.controllers.laws.lqg import LQG_LAW


class LQGSingleMass(ControllerFmu):
    """Discrete LQG with integral action and a one-sample computation delay: discrete LQR on the sampled plant, steady-state Kalman filter (IP02 single-mass cart); output the motor voltage, sampled at sample_period."""  # noqa: E501 -- this one line is the FMU's modelDescription description

    law = LQG_LAW
    kind = "single-mass"
