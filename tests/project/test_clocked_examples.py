"""The clocked example scenarios are the generated scenarios' copies (``devtools.clocked_examples``)."""
from __future__ import annotations

from devtools.clocked_examples import OUT, examples, main


def test_the_committed_clocked_examples_are_what_the_generator_writes() -> None:
    assert main(["--check"]) == 0
    assert sorted(p.name for p in OUT.iterdir() if p.is_dir()) == sorted(examples())


def test_the_clocked_examples_change_only_the_clocked_components() -> None:
    single = examples()["single-mass-lqr-clocked"]["SystemStructure.ssd"]
    assert 'source="resources/LQRSingleMassClocked.fmu"' in single
    assert 'source="resources/Setpoint.fmu"' in single and 'source="resources/IP02SingleMass.fmu"' in single
    multi = examples()["single-mass-lqr-multirate"]["SystemStructure.ssd"]
    assert 'source="resources/SetpointClocked.fmu"' in multi and '<ssv:Integer value="1"/>' in multi
