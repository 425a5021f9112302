"""``tune --install`` from an installed wheel writes the user's own copy of a shipped scenario,
never the package's folder (site-packages)."""
from __future__ import annotations

from ipcosim.harness.scenario.ssp import load_scenario
from ipcosim.harness.studies import tune
from ipcosim.harness.support import paths


def test_install_from_a_wheel_goes_to_the_users_scenario_folder(tmp_path, monkeypatch):
    monkeypatch.setattr(paths, "in_checkout", lambda: False)
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path))
    shipped = paths.SCENARIO_DIR / "single-mass-lqr"
    before = sorted(p.name for p in shipped.iterdir())
    target = tune.install_path("single-mass-lqr")
    assert target == tmp_path / "ipcosim" / "scenarios" / "single-mass-lqr" / "autotuned.ssv"
    text = (shipped / "thesis.ssv").read_text().replace('name="thesis"', 'name="autotuned"')
    tune.install("single-mass-lqr", target, text)
    assert sorted(p.name for p in shipped.iterdir()) == before  # the package is untouched
    copy = load_scenario(target.parent)
    assert "autotuned" in copy.parameter_sets and "thesis" in copy.parameter_sets


def test_install_in_a_checkout_goes_beside_the_scenario(monkeypatch):
    monkeypatch.setattr(paths, "in_checkout", lambda: True)
    assert tune.install_path("single-mass-lqr") == paths.SCENARIO_DIR / "single-mass-lqr" / "autotuned.ssv"
