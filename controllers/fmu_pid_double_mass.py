"""FMU ``PIDDoubleMass``: the thesis's single-loop PID on the motor-cart position error, for the IP02
double-mass carts."""
from ipcosim.controllers.controller_fmu import ControllerFmu
from ipcosim.controllers.laws.pid import PID_LAW


class PIDDoubleMass(ControllerFmu):
    """The thesis's single-loop PID on the motor-cart position error (IP02 double-mass carts); output the motor voltage, sampled at sample_period."""  # noqa: E501 -- this one line is the FMU's modelDescription description

    law = PID_LAW
    kind = "double-mass"
