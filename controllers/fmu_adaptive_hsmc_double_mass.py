"""FMU ``AdaptiveHSMCDoubleMass``: hierarchical sliding-mode control with time-scheduled gains, for the IP02
double-mass carts."""
from ipcosim.controllers.controller_fmu import ControllerFmu
from ipcosim.controllers.laws.hsmc import ADAPTIVE_HSMC_LAW


class AdaptiveHSMCDoubleMass(ControllerFmu):
    """Hierarchical sliding-mode control with time-scheduled gains (IP02 double-mass carts); output the motor voltage, sampled at sample_period."""  # noqa: E501 -- this one line is the FMU's modelDescription description

    law = ADAPTIVE_HSMC_LAW
    kind = "double-mass"
