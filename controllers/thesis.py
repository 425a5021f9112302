"""The thesis's LQR design data as plain numbers (the thesis, sec. 3.2.2 / 4.2.2, App. A.2 / B.3).

Kept apart from ``ipcosim.controllers.design`` (numpy, scipy) so that the parameter catalog, and
with it every controller FMU, reads them without the design stack.
"""
from __future__ import annotations

#: App. A.2 state weights for ``[xc, xc', th, th']`` (diagonal of Q): Bryson-style q_i = w / (a * x_max^2).
THESIS_SINGLE_MASS_Q_DIAGONAL = (200 / (2.534 * 0.1 ** 2), 50 / (2 * 0.09211 ** 2), 100 / (3.2 * 0.016 ** 2),
                                 0.008 / (1.1 * 0.0072 ** 2))
THESIS_SINGLE_MASS_R = 1.0 / 36.0
#: App. A.2 observer poles: 40 * [-4 +- 0.5j, -3 +- 0.2j] rad/s.
THESIS_SINGLE_MASS_OBSERVER_POLES = tuple(40 * p for p in (-4 + 0.5j, -4 - 0.5j, -3 + 0.2j, -3 - 0.2j))
#: App. B.3 state weights for ``[xa, xa', xc, xc', th, th']`` (diagonal of Q).
THESIS_DOUBLE_MASS_Q_DIAGONAL = (32.0, 0.5, 19.0, 2.0, 1700.0, 0.4)
THESIS_DOUBLE_MASS_R = 0.15 / 36.0
#: App. B.3: observer poles = observer_pole_factor * eig(A - B K) with factor 2 * 5 = 10.
THESIS_DOUBLE_MASS_OBSERVER_FACTOR = 10.0
#: Thesis ch. 4 LQR gain (printed to 1 decimal).
THESIS_DOUBLE_MASS_K = (1182.2, 38.6, -1292.9, -181.7, 885.9, 87.8)
