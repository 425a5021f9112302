"""FMU ``HSMCDoubleMass``: hierarchical sliding-mode control, for the IP02 double-mass carts."""
from ipcosim.controllers.controller_fmu import ControllerFmu
from ipcosim.controllers.laws.hsmc import HSMC_LAW


class HSMCDoubleMass(ControllerFmu):
    """Hierarchical sliding-mode control (IP02 double-mass carts); output the motor voltage, sampled at sample_period."""  # noqa: E501 -- this one line is the FMU's modelDescription description

    law = HSMC_LAW
    kind = "double-mass"
