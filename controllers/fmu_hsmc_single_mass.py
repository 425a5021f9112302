"""FMU ``HSMCSingleMass``: hierarchical sliding-mode control, for the IP02 single-mass cart."""
from ipcosim.controllers.controller_fmu import ControllerFmu
from ipcosim.controllers.laws.hsmc import HSMC_LAW


class HSMCSingleMass(ControllerFmu):
    """Hierarchical sliding-mode control (IP02 single-mass cart); output the motor voltage, sampled at sample_period."""

    law = HSMC_LAW
    kind = "single-mass"
