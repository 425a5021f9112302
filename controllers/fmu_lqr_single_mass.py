"""FMU ``LQRSingleMass``: LQR state feedback on a discrete Luenberger (current) estimator, designed at
initialization, for the IP02 single-mass cart."""
from ipcosim.controllers.controller_fmu import ControllerFmu
from ipcosim.controllers.laws.lqr import LQR_LAW


class LQRSingleMass(ControllerFmu):
    """LQR state feedback on a discrete Luenberger (current) estimator, designed at initialization (IP02 single-mass cart); output the motor voltage, sampled at sample_period."""  # noqa: E501 -- this one line is the FMU's modelDescription description

    law = LQR_LAW
    kind = "single-mass"
