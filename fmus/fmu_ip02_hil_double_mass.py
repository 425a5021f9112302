"""FMU ``IP02HILDoubleMass``: the double-mass plant's connectors on a data-acquisition card (HIL adapter)."""
from ipcosim.fmus.hil.adapter import HilFmu


class IP02HILDoubleMass(HilFmu):
    """Hardware-in-the-loop adapter for the IP02 double mass: voltage to a Q4 analog output, three encoders to positions."""  # noqa: E501 -- this one line is the FMU's modelDescription description

    kind = "double-mass"
