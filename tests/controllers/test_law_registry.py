"""The law registry's table of where each law is declared (``ipcosim.controllers.laws.ENTRIES``): the catalog
collects every entry from it, and one law's entry is found from it without importing the other laws (a run asks
only whether its controller's law has a linear model)."""
from __future__ import annotations

import subprocess
import sys

import pytest

from ipcosim.controllers import catalog
from ipcosim.controllers.laws import ENTRIES, declared
from ipcosim.fmus import kinds
from ipcosim.harness.api.task import has_linear_model


def test_every_law_is_declared_where_the_table_says_under_its_own_name() -> None:
    assert list(catalog.REGISTRY) == list(ENTRIES)
    for law in ENTRIES:
        assert declared(law).name == law
        assert declared(law) is catalog.REGISTRY[law]


def test_an_unknown_law_is_declared_nowhere() -> None:
    assert declared("LQRR") is None and declared("") is None


@pytest.mark.parametrize("law", list(ENTRIES))
def test_has_linear_model_answers_what_the_registry_says(law: str) -> None:
    entry = catalog.REGISTRY[law]
    for kind in kinds.names():
        expected = entry.linear is not None and kind in entry.sets
        assert has_linear_model(catalog.model_name(kind, law)) is expected, (law, kind)


@pytest.mark.parametrize("model", ["IP02SingleMass", "Setpoint", "SingleMass", "", "LQR", "LQRSingleMassX"])
def test_a_model_that_is_no_law_on_a_kind_has_no_linear_model(model: str) -> None:
    assert has_linear_model(model) is False


def test_one_laws_entry_imports_that_laws_module_alone() -> None:
    code = ("import sys; from ipcosim.harness.api.task import has_linear_model; "
            "assert has_linear_model('LQRSingleMass'); "
            "print(*sorted(m.rpartition('.')[2] for m in sys.modules if m.startswith('ipcosim.controllers.laws.')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["base", "lqr"]
