"""FMU ``IP02HILSingleMass``: the single-mass plant's connectors on a data-acquisition card (HIL adapter)."""
from ipcosim.fmus.hil.adapter import HilFmu


class IP02HILSingleMass(HilFmu):
    """Hardware-in-the-loop adapter for the IP02 single mass: voltage to a Q4 analog output, encoder counts to positions."""  # noqa: E501 -- this one line is the FMU's modelDescription description

    kind = "single-mass"
