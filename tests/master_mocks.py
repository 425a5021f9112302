"""Mock components for testing the master without FMUs: models, Python slaves and a builder
that turns them into a bound System (as ipcosim.harness.scenario.binding.bind would from an SSD and FMUs)."""
from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Sequence

from py_slave import PySlave

from ipcosim.harness.master.slave import DISCARD, ERROR, OK
from ipcosim.harness.master.system import Instance, Model, System, Variable
from ipcosim.harness.scenario.binding import bind
from ipcosim.harness.scenario.structure import Component, Connection, Connector, Experiment, Scenario


def model(name: str, inputs: Sequence[str] = (), outputs: Sequence[str] = (),
          parameters: dict[str, float] | None = None, feedthrough: dict[str, Sequence[str]] | None = None,
          units: dict[str, str] | None = None) -> Model:
    """A Model with Real inputs, outputs and parameters (value references in declaration order)."""
    variables: dict[str, Variable] = {}
    units = units or {}
    vr = 0
    for n in inputs:
        variables[n] = Variable(n, vr, "Real", "input", "continuous", None, units.get(n), 0.0)
        vr += 1
    for n in outputs:
        variables[n] = Variable(n, vr, "Real", "output", "continuous", "calculated", units.get(n), 0.0)
        vr += 1
    for n, v in (parameters or {}).items():
        variables[n] = Variable(n, vr, "Real", "parameter", "fixed", "exact", units.get(n), float(v))
        vr += 1
    ft = {o: frozenset((feedthrough or {}).get(o, ())) for o in outputs}
    return Model(name=name, variables=variables, feedthrough=ft, guid=f"mock-{name}")


def system(components: Sequence[tuple[str, Model]], connections: Sequence[tuple[str, str]],
           stop_time: float = 1.0, step: float = 0.01,
           bindings: dict[str, dict[str, float]] | None = None, units: dict | None = None) -> System:
    """A System of mock models; ``connections`` as ("a.y", "b.u") pairs."""
    from ipcosim.harness.scenario.structure import Parameter, ParameterSet

    comps = []
    for name, m in components:
        conns = tuple(Connector(v.name, v.causality, "Real", v.unit) for v in m.variables.values()
                      if v.causality in ("input", "output"))
        b = ()
        if bindings and name in bindings:
            b = (ParameterSet("test", tuple(Parameter(k, "Real", float(v)) for k, v in bindings[name].items())),)
        comps.append(Component(name=name, source=f"resources/{m.name}.fmu", fmu=None, connectors=conns, bindings=b))
    conns = []
    for a, b in connections:
        (ae, ac), (be, bc) = a.split("."), b.split(".")
        conns.append(Connection(ae, ac, be, bc))
    scenario = Scenario(name="mock", origin="mock.ssd", location=Path("."), description="", components=tuple(comps),
                        connections=tuple(conns), units=dict(units or {}), experiment=Experiment(0.0, stop_time, step))
    return bind(scenario, models={name: m for name, m in components})


class Behaviour(PySlave):
    """A PySlave whose behaviour is given by functions of the slave (for concise tests)."""

    def __init__(self, instance: Instance, step_fn: Callable[["Behaviour", float, float], Any] | None = None,
                 get_fn: Callable[["Behaviour"], None] | None = None,
                 exit_fn: Callable[["Behaviour"], None] | None = None) -> None:
        super().__init__(instance)
        self.vr = {n: v.vr for n, v in instance.model.variables.items()}
        self.step_fn, self.get_fn, self.exit_fn = step_fn, get_fn, exit_fn
        self.steps: list[tuple[float, float]] = []

    def __getitem__(self, name: str) -> Any:
        return self.values[self.vr[name]]

    def __setitem__(self, name: str, value: Any) -> None:
        self.values[self.vr[name]] = value

    def step(self, t: float, h: float) -> Any:
        self.steps.append((t, h))
        return self.step_fn(self, t, h) if self.step_fn else OK

    def on_get(self) -> None:
        if self.get_fn:
            self.get_fn(self)

    def on_exit_initialization(self) -> None:
        if self.exit_fn:
            self.exit_fn(self)


class Factory:
    """Slave factory keeping every slave it made (by component name)."""

    def __init__(self, **behaviours: dict[str, Any]) -> None:
        self.behaviours = behaviours
        self.slaves: dict[str, Behaviour] = {}
        self.fail_instantiate: set[str] = set()

    def __call__(self, instance: Instance) -> Behaviour:
        spec = self.behaviours.get(instance.name, {})
        slave = Behaviour(instance, **spec)
        if instance.name in self.fail_instantiate:
            def boom() -> None:
                from ipcosim.harness.master.slave import SlaveError

                slave.calls.append("instantiate-failed")
                raise SlaveError(f"component {instance.name}: fmi2Instantiate failed")
            slave.instantiate = boom  # type: ignore[method-assign]
        self.slaves[instance.name] = slave
        return slave


# ---------------------------------------------------------------- a small closed loop
# setpoint: r = amplitude after step_time; plant: x' = u (Euler, ZOH u); controller:
# u = k (r - x), sampled every sample_period (output from the inputs at the end of its step)

def loop_models() -> dict[str, Model]:
    return {
        "setpoint": model("Setpoint", outputs=["reference"], parameters={"amplitude": 1.0, "step_time": 0.0}),
        "plant": model("Plant", inputs=["voltage"], outputs=["position"], parameters={"x0": 0.0}),
        "controller": model("Controller", inputs=["reference", "position"], outputs=["voltage"],
                            parameters={"k": 5.0, "sample_period": 0.01},
                            feedthrough={"voltage": ["reference", "position"]}),
    }


LOOP_CONNECTIONS = [("setpoint.reference", "controller.reference"), ("plant.position", "controller.position"),
                    ("controller.voltage", "plant.voltage")]


def setpoint_step(s: Behaviour, t: float, h: float) -> int:
    s["reference"] = s["amplitude"] if t + h >= s["step_time"] - 1e-12 else 0.0
    return OK


def setpoint_exit(s: Behaviour) -> None:
    s["reference"] = s["amplitude"] if s["step_time"] <= 0.0 else 0.0


def plant_step(s: Behaviour, t: float, h: float) -> int:
    s["position"] = s["position"] + h * s["voltage"]
    return OK


def plant_exit(s: Behaviour) -> None:
    s["position"] = s["x0"]


def controller_step(s: Behaviour, t: float, h: float) -> int:
    s["voltage"] = s["k"] * (s["reference"] - s["position"])
    return OK


def loop_factory(**extra: dict[str, Any]) -> Factory:
    spec = {"setpoint": {"step_fn": setpoint_step, "exit_fn": setpoint_exit},
            "plant": {"step_fn": plant_step, "exit_fn": plant_exit},
            "controller": {"step_fn": controller_step, "exit_fn": lambda s: controller_step(s, 0.0, 0.0)}}
    for k, v in extra.items():
        spec[k] = {**spec.get(k, {}), **v}
    return Factory(**spec)


def loop_system(order: Sequence[str] = ("setpoint", "controller", "plant"), **kw: Any) -> System:
    models = loop_models()
    return system([(n, models[n]) for n in order], LOOP_CONNECTIONS, **kw)


__all__ = ["DISCARD", "ERROR", "OK", "Behaviour", "Factory", "LOOP_CONNECTIONS", "loop_factory", "loop_models",
           "loop_system", "model", "system"]
