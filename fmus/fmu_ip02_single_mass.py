"""FMU ``IP02SingleMass``: the Quanser IP02 single-mass cart with a free pendulum (thesis ch. 3)."""
from ipcosim.fmus.plant_fmu import PlantFmu


class IP02SingleMass(PlantFmu):
    """Quanser IP02 single-mass cart with an inverted pendulum (nonlinear, with motor inductance)."""

    kind = "single-mass"
