"""FMU ``CascadePIDSingleMass``: cascade PID: inner loop on the pendulum angle, outer loop on the cart
position, for the IP02 single-mass cart."""
from ipcosim.controllers.controller_fmu import ControllerFmu
from ipcosim.controllers.laws.pid import CASCADE_PID_LAW


class CascadePIDSingleMass(ControllerFmu):
    """Cascade PID: inner loop on the pendulum angle, outer loop on the cart position (IP02 single-mass cart); output the motor voltage, sampled at sample_period."""  # noqa: E501 -- this one line is the FMU's modelDescription description

    law = CASCADE_PID_LAW
    kind = "single-mass"
