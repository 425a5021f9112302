"""The run figure, stacked like the thesis's result figures: reference and cart position(s),
pendulum angle, motor voltage, over a shared time axis."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

    from ipcosim.harness.master.results import Result

POSITIONS = (("plant.cart_position", "cart"), ("plant.active_cart_position", "active cart"),
             ("plant.passive_cart_position", "passive cart"))


def plot_result(result: "Result", path: str | Path, title: str | None = None) -> Path:
    """Write the three-panel figure of a run (:func:`figure`) to ``path`` (PNG); returns the path."""
    fig = figure(result, title, backend="Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def figure(result: "Result", title: str | None = None, backend: str | None = None) -> "Figure":
    """The three-panel matplotlib figure of a run.

    Panels: (1) reference and cart position(s) [m], (2) pendulum angle [deg], (3) controller
    voltage [V]. Panels whose signals the result lacks are left out; with none of them, every
    recorded column is drawn in one panel.
    """
    from ipcosim.harness.errors import require

    require("matplotlib")
    import matplotlib

    if backend:
        matplotlib.use(backend)
    import matplotlib.pyplot as plt

    cols = result.columns
    t = result["time"]
    panels: list[tuple[str, list[tuple[str, np.ndarray, dict]]]] = []
    pos = [(label, result[c], {}) for c, label in POSITIONS if c in cols]
    ref = next((c for c in ("setpoint.reference", "controller.reference") if c in cols), None)
    if ref:
        pos.insert(0, ("reference", result[ref], {"linestyle": "--", "color": "k", "linewidth": 1.0}))
    if pos:
        panels.append(("position [m]", pos))
    if "plant.pendulum_angle" in cols:
        panels.append(("pendulum angle [deg]", [("angle", np.degrees(result["plant.pendulum_angle"]), {})]))
    volt = next((c for c in ("controller.voltage", "plant.voltage") if c in cols), None)
    if volt:
        panels.append(("voltage [V]", [("voltage", result[volt], {"drawstyle": "steps-post"})]))
    if not panels:
        panels.append(("value", [(c, result[c], {}) for c in cols[1:]]))
    fig, axes = plt.subplots(len(panels), 1, sharex=True, figsize=(8, 2.4 * len(panels) + 0.6), squeeze=False)
    for ax, (ylabel, lines) in zip(axes[:, 0], panels):
        for label, y, style in lines:
            ax.plot(t, y, label=label, **style)
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
        if len(lines) > 1:
            ax.legend(loc="best", fontsize="small")
    axes[-1, 0].set_xlabel("time [s]")
    meta = result.metadata
    name = title or meta.get("scenario", "")
    extra = f" ({meta['parameter_set']})" if meta.get("parameter_set") else ""
    status = "" if result.ok else "  [FAILED]"
    fig.suptitle(f"{name}{extra}{status}")
    fig.tight_layout()
    return fig
