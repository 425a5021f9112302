"""FMU ``SwingUpSingleMass``: energy swing-up from hanging with a hand-over to the thesis's LQR, IP02 single mass."""
from ipcosim.controllers.controller_fmu import ControllerFmu
from ipcosim.controllers.laws.swing_up import SWING_UP_LAW


class SwingUpSingleMass(ControllerFmu):
    """Energy swing-up from hanging, balanced by an LQR near upright (IP02 single-mass cart).

    The first line is the FMU's modelDescription description. Output: the motor voltage,
    sampled at sample_period.
    """

    law = SWING_UP_LAW
    kind = "single-mass"
