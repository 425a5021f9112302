"""FMU ``ExcitationDoubleMass``: the identification experiment's multisine voltage with a weak position hold,
for the IP02 double-mass cart (``ipcosim.controllers.laws.excitation``)."""
from ipcosim.controllers.controller_fmu import ControllerFmu
from ipcosim.controllers.laws.excitation import EXCITATION_LAW


class ExcitationDoubleMass(ControllerFmu):
    """Identification excitation: seeded multisine voltage plus a weak hold of the motor-driven cart (IP02 double-mass cart); output the motor voltage, sampled at sample_period."""  # noqa: E501 -- this one line is the FMU's modelDescription description

    law = EXCITATION_LAW
    kind = "double-mass"
