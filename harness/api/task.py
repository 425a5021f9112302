"""What the IP02 task adds to a run of the generic master, before it runs: whether a controller is a law
with a linear model (then a plant without Coulomb friction or encoder counts has no residual cycle), the
value a run starts a variable with, and the task metrics with the run's amplitude bound beside them
(``docs/metrics.md``; the metrics themselves are :mod:`ipcosim.fmus.metrics`'s)."""
from __future__ import annotations

from typing import Any, Mapping

from ipcosim.fmus.metrics import BOUND_KEYS
from ipcosim.harness.master.recorder import TaskMetrics
from ipcosim.harness.master.system import System


def has_linear_model(model: str) -> bool:
    """Whether the controller FMU ``model`` (``LQRSingleMass``) is a law of the registry with a linear model
    (``<Law><Plant>``: the law's module alone is imported, not the registry's every law)."""
    from ipcosim.controllers.laws import declared
    from ipcosim.fmus.kinds import get, names

    for kind in names():
        suffix = get(kind).suffix
        e = declared(model[:len(model) - len(suffix)]) if model.endswith(suffix) else None
        if e is not None and e.linear is not None and kind in e.sets:
            return True
    return False


def with_bound(task_metrics: TaskMetrics | None, metadata: Mapping[str, Any]) -> TaskMetrics | None:
    """The task metrics with the run's amplitude bound beside them (``docs/metrics.md``), where there are any."""
    if task_metrics is None:
        return None
    bound = {k: metadata[k] for k in BOUND_KEYS}

    def measured(*args: Any, **kwargs: Any) -> dict[str, Any]:
        out = dict(task_metrics(*args, **kwargs))
        return {**out, **bound} if out else out

    return measured


def start_value(system: System, values: Mapping[tuple[str, str], Any], component: str, variable: str) -> Any:
    """The value ``component.variable`` starts a run with (its ``values`` entry, else its bound start), or None."""
    try:
        inst = system.instance(component)
    except KeyError:
        return None
    if variable not in inst.model.variables:
        return None
    return values.get((component, variable), inst.start_value(variable))
