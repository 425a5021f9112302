"""A sweep's size is known before any run is made: too many runs are refused at once, in one line
naming the options and the size, without allocating the cases."""
from __future__ import annotations

import time
import tracemalloc

import pytest

from ipcosim.harness.api.grammar import VaryError, parse_all
from ipcosim.harness.cli import main as cli_main
from ipcosim.harness.studies.cases import MAX_RUNS, make_cases, sweep_size

NOMINAL = {"plant.Mp": 0.127, "plant.Beq": 4.3}


def test_the_size_is_the_product_of_the_grids_and_lists_times_the_samples():
    varies = parse_all(["plant.Mp=grid(0.1,0.3,7)", "plant.Beq=[4,5,6]"], NOMINAL)
    assert sweep_size(varies, 2) == 7 * 3 * 2
    assert len(make_cases(varies, NOMINAL, samples=2)) == 42
    assert sweep_size(parse_all(["plant.Mp=uniform(0.1,0.3)"], NOMINAL), 5) == 5


def test_a_hundred_million_point_grid_is_refused_at_once_without_memory():
    varies = parse_all(["plant.Mp=grid(0.1,0.3,100000000)"], NOMINAL)
    tracemalloc.start()
    t0 = time.process_time()
    with pytest.raises(VaryError) as err:
        make_cases(varies, NOMINAL)
    cpu = time.process_time() - t0
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert cpu < 0.5 and peak < 1_000_000  # nothing of the 10^8 points was made
    text = str(err.value)
    assert "--vary" in text and "100000000 runs" in text and str(MAX_RUNS) in text


def test_a_grid_times_samples_over_the_limit_names_the_samples():
    varies = parse_all(["plant.Mp=grid(0.1,0.3,1001)"], NOMINAL)
    with pytest.raises(VaryError, match=r"--samples 100\b"):
        make_cases(varies, NOMINAL, samples=100)  # 100 100 runs
    assert len(make_cases(varies, NOMINAL, samples=99)) == 1001 * 99 <= MAX_RUNS


def test_the_command_refuses_in_one_line_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "sweep"
    code = cli_main(["sweep", "pure:single-mass-lqr", "--vary", "plant.Mp=grid(0.1,0.3,100000000)",
                     "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert "--vary" in err[0] and "100000000 runs" in err[0]
    assert not (out / "results.csv").exists()
