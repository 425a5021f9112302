"""The control laws as linear discrete-time systems, for the loop analyses.

Each law module of ``ipcosim.controllers.laws`` transcribes its law's per-sample arithmetic, line by
line, into a linear state-space model ``x[k+1] = A x[k] + B y[k]``, ``u[k] = C x[k] + D y[k]`` from the
measured positions ``y`` (the plant kind's ``MEASURED`` order) to the voltage ``u``, with the reference
held at 0 (the loop is analysed about the upright equilibrium), written with the builder of
``ipcosim.controllers.linear``. What is not linear is replaced by its linearization at rest, and said so
in ``LinearLaw.notes``: the voltage limit is left out, HSMC's ``eta tanh(g S)`` becomes ``eta g S``, and
the adaptive HSMC's schedules are frozen at their final values (t -> infinity). Each model is checked
against the law it transcribes (docs/studies.md, ``ipcosim analyze``): both driven by the same small random
measurements give the same voltages, to 1e-7.
"""
from __future__ import annotations

from ipcosim.controllers.catalog import entry_of
from ipcosim.controllers.laws.base import DiscreteLaw
from ipcosim.controllers.linear import Builder, LinearizationError, LinearLaw


def linear_law(law: DiscreteLaw) -> LinearLaw:
    """The law's linear model from the measurements to the voltage (reference 0, no limit).

    Parameters
    ----------
    law : DiscreteLaw
        A PID, CascadePID, LQR, LQG, HSMC or AdaptiveHSMC of ``ipcosim.controllers.laws``.

    Returns
    -------
    LinearLaw

    Raises
    ------
    LinearizationError
        For a law class without a linear model (its registry entry has none).
    """
    entry = entry_of(law)
    if entry is None or entry.linear is None:
        raise LinearizationError(f"no linear model for the law {type(law).__name__}")
    b = Builder(len(law.measured))
    u, notes = entry.linear(law, b)
    A, B, C, D = b.realize(u)
    notes = ["voltage limit left out (small signals)"] + notes
    return LinearLaw(A, B, C, D, law.sample_period, tuple(law.measured), tuple(notes))


__all__ = ["LinearLaw", "LinearizationError", "linear_law"]
