"""FMU ``CascadePIDDoubleMass``: cascade PID: inner loop on the pendulum angle, outer loop on the cart
position, for the IP02 double-mass carts."""
from ipcosim.controllers.controller_fmu import ControllerFmu
from ipcosim.controllers.laws.pid import CASCADE_PID_LAW


class CascadePIDDoubleMass(ControllerFmu):
    """Cascade PID: inner loop on the pendulum angle, outer loop on the cart position (IP02 double-mass carts); output the motor voltage, sampled at sample_period."""  # noqa: E501 -- this one line is the FMU's modelDescription description

    law = CASCADE_PID_LAW
    kind = "double-mass"
