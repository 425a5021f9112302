"""Coulomb friction limit cycles of a scenario's sampled loop, predicted by the describing function.

Coulomb friction on a cart is a relay on the cart's velocity: ``-b sign(v)``. Its describing function
is ``N(A) = 4 b / (pi A)`` for a velocity of amplitude ``A``, real and positive, so the harmonic balance
``1 + N(A) G(jw) = 0`` of the loop closed around the relay has a solution wherever ``G``, the closed
loop's response from a force pushing that cart to the cart's velocity, crosses the negative real axis
(Slotine & Li, *Applied Nonlinear Control*, ch. 5; for the inverted pendulum, Campbell, Crawford &
Morris, "Friction and the inverted pendulum stabilization problem", *ASME J. Dyn. Syst. Meas. Control*
130(5), 2008). At such a crossing ``w``, the loop hunts at ``w`` with the cart's velocity amplitude
``A = 4 b |G(jw)| / pi``, and every other signal with its own response to the same first harmonic of
the friction force. What the prediction leaves out: the harmonics of the relay (the describing function
keeps the first), static friction above the kinetic level (the plant's breakaway equals its kinetic
force), the other carts' friction (each cart is taken alone), and whether the cycle is stable.

The loop is ``ipcosim.harness.analysis.analyze``'s: the plant linearized about upright with the motor
inductance, sampled with a zero-order hold at the law's period, closed by the law's linear transcription
(``ipcosim.harness.analysis.linear_law``). A law's own friction compensation is nonlinear and is not in that
transcription, so the prediction is that of the law without it.
"""
from __future__ import annotations

import cmath
import math
from typing import Any, Mapping

import control
import numpy as np

from ipcosim.fmus.instruments import realism
from ipcosim.fmus.linearize import COULOMB_CARTS, force_columns, linearize
from ipcosim.fmus.params import DEFAULT_PRESET, PlantParams, preset
from ipcosim.fmus.physics import MEASURED

#: Frequencies searched for a crossing [rad/s]: from here to the Nyquist frequency.
LOWEST_RAD_S = 0.05
#: Points of the (log-spaced) search grid.
GRID_POINTS = 4000


def plant_of(loop: Any) -> PlantParams:
    """The plant of ``loop``: its kind's default preset with the loop's plant values."""
    return preset(DEFAULT_PRESET[loop.kind], **dict(loop.plant_values))


def sampled_plant(params: PlantParams, T: float) -> tuple[Any, list, np.ndarray, np.ndarray]:
    """The plant's linearization (with the inductance), its force columns (a force pushing each cart with
    Coulomb friction) and its zero-order-hold discretization at ``T`` [s] with the voltage and those forces
    as inputs: ``(model, forces, Ad, Bd)``."""
    model = linearize(params, inductance=True)
    forces = force_columns(params)
    n = len(model.states)
    B = np.hstack([model.B, np.array([c for _, c in forces]).T])
    sampled = control.c2d(control.ss(model.A, B, np.eye(n), np.zeros((n, B.shape[1]))), T, method="zoh")
    return model, forces, np.asarray(sampled.A), np.asarray(sampled.B)


def closed_loop(loop: Any) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """The sampled closed loop of ``loop`` (``analyze.Loop``) with a force pushing each cart as input
    (:data:`~ipcosim.fmus.linearize.COULOMB_CARTS` order): ``(Phi, Gamma, plant state names)``; the first
    states of ``Phi`` are the plant's, then the law's."""
    model, forces, Ad, Bd = sampled_plant(plant_of(loop), loop.T)
    n = len(model.states)
    law = loop.controller
    Ac, Bc, Cc, Dc = (np.atleast_2d(np.asarray(m, dtype=float)) for m in (law.A, law.B, law.C, law.D))
    C = np.asarray(model.C)
    m = Ac.shape[0]
    phi = np.zeros((n + m, n + m))
    phi[:n, :n] = Ad + Bd[:, :1] @ Dc @ C    # u = Cc xc + Dc y, y = C x
    phi[:n, n:] = Bd[:, :1] @ Cc
    phi[n:, :n] = Bc @ C
    phi[n:, n:] = Ac
    gamma = np.vstack([Bd[:, 1:], np.zeros((m, len(forces)))])
    return phi, gamma, model.states


def coulomb_forces(loop: Any) -> tuple[dict[str, float], str]:
    """The Coulomb force of each cart [N] the prediction uses and where it comes from: the plant's values
    where any is set, else the lab bench's (``ipcosim.fmus.instruments.realism('lab')``)."""
    params, names = plant_of(loop), [name for name, _ in COULOMB_CARTS[loop.kind]]
    values = {n: float(getattr(params, n)) for n in names}
    if any(v > 0 for v in values.values()):
        return values, "the plant's parameters"
    lab = realism("lab", loop.kind)[1]
    return {n: float(lab[n]) for n in names}, "the lab bench's (the plant has none)"


def predict(loop: Any, forces: Mapping[str, float] | None = None) -> list[dict[str, Any]]:
    """The limit cycles the describing function predicts for each cart's Coulomb friction alone.

    Parameters
    ----------
    loop : analyze.Loop
        A loop whose closed loop is stable.
    forces : mapping, optional
        Coulomb force [N] per friction parameter (``b``; ``b1``, ``b2``); default :func:`coulomb_forces`.

    Returns
    -------
    list of dict
        One per crossing: ``parameter``, ``coulomb_force_N``, ``frequency_Hz``, ``velocity_amplitude_m_s``
        of the rubbing cart, and ``amplitudes`` of the measured signals (``MEASURED`` names, [m] or [rad]).

    Examples
    --------
    >>> from ipcosim.harness.analysis.analyze import scenario_loop
    >>> loop, _ = scenario_loop("double-mass-lqg", "tuned")                 # doctest: +SKIP
    >>> [round(c["frequency_Hz"], 2) for c in predict(loop)]                # doctest: +SKIP
    [0.51, 0.55]
    """
    phi, gamma, states = closed_loop(loop)
    if forces is None:
        forces = coulomb_forces(loop)[0]
    measured = [states.index(s) for s in MEASURED[loop.kind]]
    eye = np.eye(phi.shape[0])
    w = np.logspace(math.log10(LOWEST_RAD_S), math.log10(math.pi / loop.T), GRID_POINTS)[:-1]
    responses = np.array([np.linalg.solve(cmath.exp(1j * wi * loop.T) * eye - phi, gamma) for wi in w])
    cycles = []
    for j, (name, velocity_state) in enumerate(COULOMB_CARTS[loop.kind]):
        H = responses[:, :, j]
        G = H[:, states.index(velocity_state)]
        for i in np.nonzero((G.imag[:-1] * G.imag[1:] < 0))[0]:
            f = G.imag[i] / (G.imag[i] - G.imag[i + 1])
            g = G[i] + f * (G[i + 1] - G[i])
            if g.real >= 0:
                continue
            first_harmonic = 4.0 * forces[name] / math.pi      # of the relay's force
            h = H[i] + f * (H[i + 1] - H[i])
            cycles.append({"parameter": name, "coulomb_force_N": float(forces[name]),
                           "frequency_Hz": float(w[i] + f * (w[i + 1] - w[i])) / (2 * math.pi),
                           "velocity_amplitude_m_s": float(abs(g) * first_harmonic),
                           "amplitudes": {states[k]: float(abs(h[k]) * first_harmonic) for k in measured}})
    return cycles


def report(loop: Any, stable: bool) -> dict[str, Any] | None:
    """The ``friction_limit_cycles`` entry of ``ipcosim analyze``: the forces used, their source and the
    predicted cycles (none computed for an unstable loop); None for a loop around no IP02 plant kind."""
    if loop.kind not in COULOMB_CARTS:
        return None
    forces, source = coulomb_forces(loop)
    out: dict[str, Any] = {"method": "describing function of each cart's Coulomb friction alone, law without its "
                                     "friction compensation", "coulomb_forces_N": forces, "forces_from": source}
    out["cycles"] = predict(loop, forces) if stable else None
    return out
