"""The passive-cart Coulomb friction that reproduces the thesis's double-mass HSMC steady-state error.

The thesis (4.2.3, Fig. 4.11, a simulation of its App. B.5 code) reports that its double-mass HSMC
"always has a steady-state error of 0.005575 m". Its plant equations carry Coulomb terms
``b1 sign(xa')``, ``b2 sign(xc')`` whose values it does not give. Without Coulomb friction the law
(reference in error coordinates) converges to the reference; a Coulomb force on the passive cart,
which the spring must overcome through a deflection the law cannot see in its error coordinates,
leaves a lasting offset. ``fit_passive_cart_friction`` finds the ``b2`` for which the pure loop
(``ipcosim.controllers.simulate``: thesis-ch4 plant, thesis HSMC set, 0 -> 0.05 m step) ends with
the thesis's error, measured as DESIGN.md's ``steady_state_error_m`` (|mean(xa - r)| over the last
10 % of the run). The value is *fitted*, not measured: ``ipcosim.fmus.params`` labels it so.
"""
from __future__ import annotations

from dataclasses import dataclass

THESIS_DOUBLE_MASS_HSMC_ERROR = 0.005575  # m, thesis 4.2.3


@dataclass(frozen=True)
class FrictionFit:
    """Fitted passive-cart Coulomb force ``b2`` [N] and the error it gives over ``stop_time``."""

    b2: float
    steady_state_error_m: float
    stop_time: float


def hsmc_error(b2: float, stop_time: float = 20.0) -> float:
    """Steady-state error [m] of the thesis double-mass HSMC on thesis-ch4 with passive-cart Coulomb ``b2`` [N]."""
    from ipcosim.controllers.catalog import make_law
    from ipcosim.controllers.simulate import run_loop
    from ipcosim.fmus.params import preset

    result = run_loop(make_law("double-mass", "HSMC", "thesis"), preset("thesis-ch4", b2=b2), stop_time=stop_time)
    return float(result.metrics["steady_state_error_m"])


def fit_passive_cart_friction(target: float = THESIS_DOUBLE_MASS_HSMC_ERROR, stop_time: float = 20.0,
                              bracket: tuple[float, float] = (0.10, 0.105), xtol: float = 1e-5) -> FrictionFit:
    """``b2`` [N] with ``hsmc_error(b2) = target`` (Brent's method inside ``bracket``).

    With stick-slip friction the error is not monotonic in ``b2`` (where the carts stick depends on
    how the last swing ends): it stays below 0.5 mm up to about 0.1006 N and rises through the
    thesis's value by 0.105 N; the bracket is that rise.
    """
    from scipy.optimize import brentq

    b2 = float(brentq(lambda b: hsmc_error(b, stop_time) - target, *bracket, xtol=xtol))
    return FrictionFit(round(b2, 4), hsmc_error(round(b2, 4), stop_time), stop_time)


if __name__ == "__main__":
    print(fit_passive_cart_friction())
