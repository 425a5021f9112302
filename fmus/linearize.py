"""Linearization of the nonlinear plants about the upright equilibrium.

The Jacobians are taken from the same right-hand side the simulation integrates
(``ipcosim.fmus.physics``), by central differences (step 1e-6; the model is smooth, so the
truncation error is ~1e-12 relative). Coulomb friction is left out (b = 0), as in the
thesis: it has no derivative at rest.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

from ipcosim.fmus import kinds
from ipcosim.fmus.params import PlantParams, plant_kind_of
from ipcosim.fmus.physics import MEASURED, rhs_for, rhs_no_inductance, state_names

if TYPE_CHECKING:
    import numpy as np


@dataclass(frozen=True)
class LinearModel:
    """Continuous-time state-space model ``x' = A x + B u, y = C x + D u``."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    states: tuple[str, ...]
    outputs: tuple[str, ...]

    @property
    def poles(self) -> np.ndarray:
        """Eigenvalues of A, sorted by real part (descending)."""
        import numpy as np  # noqa: PLC0415 -- numpy only where arrays are asked for

        ev = np.linalg.eigvals(self.A)
        return ev[np.lexsort((ev.imag, -ev.real))]

    def to_json_dict(self) -> dict:
        """The ``ipcosim linearize --json`` document (docs/plant.md: the A, B, C, D, states, outputs and poles)."""
        return {"A": self.A.tolist(), "B": self.B.tolist(), "C": self.C.tolist(), "D": self.D.tolist(),
                "states": list(self.states), "outputs": list(self.outputs),
                "poles": [[float(p.real), float(p.imag)] for p in self.poles]}


def _jacobian(f: Any, n: int, eps: float = 1e-6) -> tuple[list[list[float]], list[float]]:
    """Central-difference Jacobians ``(A, B)`` of ``f(x, u)`` at ``x = 0, u = 0``, in plain floats."""
    zero = [0.0] * n
    cols = []
    for j in range(n):
        dx = [0.0] * n
        dx[j] = eps
        fp = f(dx, 0.0)
        dx[j] = -eps
        fm = f(dx, 0.0)
        cols.append([(a - b) / (2 * eps) for a, b in zip(fp, fm)])
    B = [(a - b) / (2 * eps) for a, b in zip(f(zero, eps), f(zero, -eps))]
    return [list(row) for row in zip(*cols)], B


#: The Coulomb friction of each cart: (plant parameter, the cart's velocity state), per plant kind.
COULOMB_CARTS = kinds.ByKind(lambda k: tuple((cart.coulomb, cart.velocity) for cart in k.carts))


def force_columns(params: PlantParams) -> list[tuple[str, list[float]]]:
    """What a force of 1 N pushing each cart adds to the state derivative at the upright equilibrium:
    ``[(friction parameter, column), ...]`` in :data:`COULOMB_CARTS` order.

    Taken from the right-hand side's own Coulomb term: the derivative with the cart sliding forward
    against a kinetic force of 1 N, less the same without friction (friction enters the equations
    additively, so the difference is exact, whatever the velocity).
    """
    kind = plant_kind_of(params)
    names = state_names(kind)
    rhs = rhs_for(params)
    free = replace(params, **{n: 0.0 for n, _ in COULOMB_CARTS[kind]})
    out = []
    for name, velocity in COULOMB_CARTS[kind]:
        x = [0.0] * len(names)
        x[names.index(velocity)] = 2.0 * params.coulomb_velocity + 1e-3   # sliding: the kinetic force
        rubbing = replace(free, **{name: 1.0})
        out.append((name, [a - b for a, b in zip(rhs(tuple(x), 0.0, free), rhs(tuple(x), 0.0, rubbing))]))
    return out


def linear_matrices(params: PlantParams, inductance: bool = True
                    ) -> tuple[list[list[float]], list[float], tuple[str, ...], tuple[str, ...]]:
    """``(A, B, states, outputs)`` of :func:`linearize` as plain lists (no numpy: the FMU runtime uses it).

    ``B`` is the single input column as a list; the outputs are the measured positions (``C``
    selects them).
    """
    kind = plant_kind_of(params)
    p = replace(params, **{name: 0.0 for name, _ in COULOMB_CARTS[kind]})
    names = state_names(kind)
    if inductance:
        rhs = rhs_for(p)
        f = lambda x, u: rhs(tuple(x), u, p)  # noqa: E731
    else:
        names = names[:-1]
        f = lambda x, u: rhs_no_inductance(tuple(x), u, p)  # noqa: E731
    A, B = _jacobian(f, len(names))
    return A, B, tuple(names), tuple(MEASURED[kind])


def linearize(params: PlantParams, inductance: bool = True) -> LinearModel:
    """Linearize a plant about the upright equilibrium (all states 0, voltage 0).

    Parameters
    ----------
    params : SingleMassParams or DoubleMassParams
        Physical parameters (``ipcosim.fmus.params.preset``).
    inductance : bool
        Keep the motor current as a state (5 or 7 states). If False the inductance is
        neglected and the current eliminated algebraically (4 or 6 states), as in the
        thesis's App. A.2 and B.3 designs.

    Returns
    -------
    LinearModel
        States in ``ipcosim.fmus.physics`` order (current last); outputs are the measured positions.
    """
    import numpy as np  # noqa: PLC0415 -- the analysis tools' arrays; the FMU runtime uses linear_matrices

    A, B, names, outputs = linear_matrices(params, inductance)
    C = np.zeros((len(outputs), len(names)))
    for r, name in enumerate(outputs):
        C[r, names.index(name)] = 1.0
    D = np.zeros((len(outputs), 1))
    return LinearModel(A=np.array(A), B=np.array(B).reshape(len(names), 1), C=C, D=D, states=names, outputs=outputs)
