"""FMU ``AdaptiveHSMCSingleMass``: hierarchical sliding-mode control with time-scheduled gains, for the IP02
single-mass cart."""
from ipcosim.controllers.controller_fmu import ControllerFmu
from ipcosim.controllers.laws.hsmc import ADAPTIVE_HSMC_LAW


class AdaptiveHSMCSingleMass(ControllerFmu):
    """Hierarchical sliding-mode control with time-scheduled gains (IP02 single-mass cart); output the motor voltage, sampled at sample_period."""  # noqa: E501 -- this one line is the FMU's modelDescription description

    law = ADAPTIVE_HSMC_LAW
    kind = "single-mass"
