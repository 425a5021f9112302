"""FMU ``IP02DoubleMass``: the IP02 active cart spring-coupled to a passive cart with a pendulum (thesis ch. 4)."""
from ipcosim.fmus.plant_fmu import PlantFmu


class IP02DoubleMass(PlantFmu):
    """Quanser IP02 double-mass (spring-coupled carts) with an inverted pendulum (nonlinear, with motor inductance)."""

    kind = "double-mass"
