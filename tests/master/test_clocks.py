"""Clock ticks computed exactly, and the clock kinds the master refuses by name (FMI 3.0, 2.2.8)."""
from __future__ import annotations

from fractions import Fraction

import pytest

from ipcosim.harness.master.algorithm import TimeBase
from ipcosim.harness.master.clocks import ClockError, clock_multiple, parse_clocking, tick_multiple


def _md(clocks: str) -> bytes:
    return (f'<fmiModelDescription fmiVersion="3.0" modelName="M" instantiationToken="x">'
            f'<CoSimulation modelIdentifier="M" hasEventMode="true"/><ModelVariables>'
            f'<Float64 name="time" valueReference="0" causality="independent" variability="continuous"/>{clocks}'
            f'<Float64 name="u" valueReference="9" causality="input" variability="discrete" clocks="1" start="0"/>'
            f'</ModelVariables><ModelStructure/></fmiModelDescription>').encode()


def _clock(vr: int, interval: str, shift: str = "0", kind: str = "constant") -> str:
    return (f'<Clock name="c{vr}" valueReference="{vr}" causality="input" variability="discrete" '
            f'intervalVariability="{kind}" intervalDecimal="{interval}" shiftDecimal="{shift}"/>')


def test_a_million_ticks_of_1ms_and_0_3ms_clocks_land_exactly() -> None:
    clocking = parse_clocking(_md(_clock(1, "0.001") + _clock(2, "0.0003")), "M")
    fast, slow = clocking.clocks[1], clocking.clocks[0]
    n = 10 ** 6
    assert slow.tick(n) == Fraction(1000) and float(slow.tick(n)) == 1000.0
    assert fast.tick(n) == Fraction(300) and float(fast.tick(n)) == 300.0
    accumulated = 0.0
    for _ in range(n):  # what a master adding the interval would reach instead
        accumulated += 0.0003
    assert accumulated != 300.0
    # every tick of both is a communication point of the master's 0.1 ms time base, to the last bit
    step = Fraction(1, 10000)
    assert tick_multiple(slow, step, "M") == (0, 10) and tick_multiple(fast, step, "M") == (0, 3)
    assert clock_multiple(clocking.inputs(), step, "M") == 1
    base = TimeBase.make(0.0, 1000.0, 1e-4)
    for i in (*range(0, n, 9973), n - 1, n):
        assert base.time(3 * i) == float(fast.tick(i)) == float(Fraction(3 * i, 10000))
        assert base.time(10 * i) == float(slow.tick(i)) == i / 1000


def test_shift_and_gcd_of_two_clocks() -> None:
    clocking = parse_clocking(_md(_clock(1, "0.01", shift="0.002") + _clock(2, "0.004")), "M")
    assert clocking.clocks[0].tick(3, Fraction(1)) == Fraction(1) + Fraction(2, 1000) + 3 * Fraction(1, 100)
    assert clock_multiple(clocking.inputs(), Fraction(1, 1000), "M") == 2
    with pytest.raises(ClockError, match="c1 .*ticks between the communication points of step 0.003"):
        clock_multiple(clocking.inputs(), Fraction(3, 1000), "M")


@pytest.mark.parametrize("kind, words", [("changing", "changing aperiodic"), ("countdown", "countdown aperiodic"),
                                         ("triggered", "triggered input clock")])
def test_unsupported_clock_kinds_are_refused_by_name(kind: str, words: str) -> None:
    xml = _md(f'<Clock name="tick" valueReference="1" causality="input" intervalVariability="{kind}"/>')
    with pytest.raises(ClockError, match=f"M: clock tick is a {words}.*not supported"):
        parse_clocking(xml, "M")


def test_a_periodic_clock_without_interval_is_refused() -> None:
    xml = _md('<Clock name="tick" valueReference="1" causality="input" intervalVariability="tunable"/>')
    with pytest.raises(ClockError, match="clock tick \\(tunable\\) gives no intervalDecimal"):
        parse_clocking(xml, "M")


def test_clocks_without_co_simulation_are_refused() -> None:
    xml = _md(_clock(1, "0.001")).replace(b'<CoSimulation modelIdentifier="M" hasEventMode="true"/>',
                                           b'<ScheduledExecution modelIdentifier="M"/>')
    with pytest.raises(ClockError, match="scheduled execution is not supported"):
        parse_clocking(xml, "M")
