"""Test FMU ``SlowInitLQGDoubleMass``: the LQG controller of the double mass, whose initialization
takes ``INIT_DELAY`` seconds on purpose (a stand-in for a slow design step, a slow licence check...).
Used by the real-time HIL swap test: the watchdog of the HIL adapter must not run during it."""
import time

from ipcosim.controllers.controller_fmu import ControllerFmu
from ipcosim.controllers.laws.lqg import LQG_LAW

INIT_DELAY = 3.0   # [s]


class SlowInitLQGDoubleMass(ControllerFmu):
    """LQG of the IP02 double mass whose initialization sleeps INIT_DELAY seconds (test only)."""

    law = LQG_LAW
    kind = "double-mass"

    def setup(self) -> None:
        time.sleep(INIT_DELAY)
        super().setup()
