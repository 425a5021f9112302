"""The control laws read a plant kind's layout from the kind registry (``ipcosim.fmus.kinds``): its carts and
its measured signals, not its name; what the thesis gives a law for a kind is looked up by the kind, and a kind
it gives nothing for is an error naming the kind, never the single mass."""
from __future__ import annotations

import dataclasses
import importlib.util
import math
import sys
from pathlib import Path
from types import ModuleType

import pytest

from ipcosim.controllers.catalog import make_law
from ipcosim.controllers.errors import ControllerParameterError
from ipcosim.controllers.laws.base import LawParameterError
from ipcosim.controllers.laws.hsmc import HSMC, thesis_hsmc, thesis_hsmc_gains, thesis_subsystem_models
from ipcosim.fmus import kinds

TOY = Path(__file__).resolve().parents[1] / "data" / "kinds" / "crane.py"


@pytest.fixture(scope="module")
def crane() -> ModuleType:
    spec = importlib.util.spec_from_file_location("_toy_crane_kind_laws", TOY)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def _relabelled(kind: str, name: str) -> kinds.PlantKind:
    """``kind`` under another name, its encoders listed in the reverse order."""
    base = kinds.get(kind)
    params = dataclasses.make_dataclass(f"{name}Params", [], bases=(base.params,), frozen=True)
    return dataclasses.replace(base, name=name, suffix=name.title().replace("-", ""), params=params,
                               measured=tuple(reversed(base.measured)), presets={})


def _voltages(law: HSMC, readings: list[list[float]], order: list[int]) -> list[float]:
    return [law.step([y[j] for j in order], 0.05) for y in readings]


def test_the_hsmc_finds_its_subsystems_by_the_kinds_measured_signals() -> None:
    """Relabelling: the same plant with its encoders listed in another order is the same loop. The law fed the
    permuted readings gives, sample for sample, the very voltages of the original (both kinds' layers are found
    by signal name; a law reading fixed positions would mix the pendulum with a cart)."""
    readings = [[0.01 * math.sin(0.03 * k), 0.012 * math.sin(0.03 * k + 0.2), 0.02 * math.cos(0.05 * k)]
                for k in range(300)]
    gains, models = thesis_hsmc_gains("double-mass"), thesis_subsystem_models("double-mass")
    with kinds.registered(_relabelled("double-mass", "double-mass-reversed")) as reversed_kind:
        assert reversed_kind.measured == ("pendulum_angle", "passive_cart_position", "active_cart_position")
        original = _voltages(HSMC("double-mass", gains, models), readings, [0, 1, 2])
        relabelled = _voltages(HSMC("double-mass-reversed", gains, models), readings, [2, 1, 0])
    assert relabelled == original
    assert max(map(abs, original)) > 0.1  # the readings did drive the law


def test_the_hsmc_layers_follow_the_kinds_carts() -> None:
    """Two carts: three sliding layers, so three surface slopes; a set of two is refused, naming the kind."""
    gains = thesis_hsmc_gains("single-mass")  # two slopes, one layer weight
    with pytest.raises(LawParameterError, match="HSMC on the double-mass plant needs 3 surface slopes c, got 2"):
        HSMC("double-mass", gains, thesis_subsystem_models("double-mass"))


def test_a_kind_without_the_theses_constants_is_an_error_naming_it(crane: ModuleType) -> None:
    with kinds.registered(crane.KIND):
        with pytest.raises(LawParameterError, match="no thesis constants for plant kind 'crane'"):
            thesis_hsmc("crane")
        with pytest.raises(ControllerParameterError, match="HSMC is not available for the crane plant"):
            make_law("crane", "HSMC")
    with pytest.raises(kinds.UnknownKindError, match="unknown plant kind 'crane'"):
        thesis_hsmc("crane")
