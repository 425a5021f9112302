"""FMU ``PIDSingleMass``: the thesis's single-loop PID on the motor-cart position error, for the IP02
single-mass cart."""
from ipcosim.controllers.controller_fmu import ControllerFmu
from ipcosim.controllers.laws.pid import PID_LAW


class PIDSingleMass(ControllerFmu):
    """The thesis's single-loop PID on the motor-cart position error (IP02 single-mass cart); output the motor voltage, sampled at sample_period."""  # noqa: E501 -- this one line is the FMU's modelDescription description

    law = PID_LAW
    kind = "single-mass"
