"""Test FMU ``SlowInitHSMCDoubleMass``: the HSMC controller of the double mass, whose initialization
takes ``INIT_DELAY`` seconds on purpose (a stand-in for a slow design step, a slow licence check...).
Used by the real-time HIL swap test: the watchdog of the HIL adapter must not run during it."""
import time

from ipcosim.controllers.controller_fmu import ControllerFmu
from ipcosim.controllers.laws.hsmc import HSMC_LAW

INIT_DELAY = 3.0   # [s]


class SlowInitHSMCDoubleMass(ControllerFmu):
    """HSMC of the IP02 double mass whose initialization sleeps INIT_DELAY seconds (test only)."""

    law = HSMC_LAW
    kind = "double-mass"

    def setup(self) -> None:
        time.sleep(INIT_DELAY)
        super().setup()
