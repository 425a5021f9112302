"""FMU ``AdaptiveHSMCDoubleMass``: hierarchical sliding-mode control with time-scheduled gains, for the IP02
double-mass carts."""
from ipcosim.controllers.controller_fmu import ControllerFmu


class AdaptiveHSMCDoubleMass(ControllerFmu):
    """Hierarchical sliding-mode control with time-scheduled gains (IP02 double-mass carts); output the motor voltage, sampled at sample_period."""  # noqa: E501 -- this one line is the FMU's modelDescription description

    law = "AdaptiveHSMC"
    kind = "double-mass"
