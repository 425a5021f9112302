"""What the record holds for a connected input (``docs/master.md``, "What an input's column holds"):
the value its connection delivers at the row's time, i.e. the source's output at ``t_n`` through the
connection's transformation (SSP 1.0 4.5.2 LinearTransformation: ``target = factor * source +
offset``); under Jacobi that is the value the FMU uses in its step from ``t_n``, so its output at
``t_n+1`` is computed from the input recorded at ``t_n``. Source: ``Source3`` (FMI 3.0, ``y`` = 0
before ``step_time`` = 0.5 s and ``amplitude`` = 1 from then on), into the FMI 3.0 adder
``y = k1*u1 + k2*u2``."""
from __future__ import annotations

import shutil

import adder_fmus
import cfmu
import numpy as np
import pytest
import ssp_text as t

import ipcosim

pytestmark = [pytest.mark.skipif(shutil.which("gcc") is None and shutil.which("cc") is None,
                                 reason="needs a C compiler to build the test FMUs"),
              pytest.mark.filterwarnings("ignore::ipcosim.harness.scenario.binding.UnconnectedInputWarning")]

FACTOR, OFFSET = 2.0, 0.5
STEP_TIME, AMPLITUDE, H, STOP = 0.5, 1.0, 0.1, 1.0


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_connected_input_is_recorded_as_the_value_exchanged_at_its_row(algorithm, tmp_path):
    out = tmp_path / "fmus"
    out.mkdir()
    src, add = cfmu.build(cfmu.SOURCE3, out), cfmu.build(adder_fmus.adder("Adder3", "3.0"), out)
    src_conn = "<ssd:Connectors>" + t.connector("y", "output", "2.0") + "</ssd:Connectors>"
    root = t.system("root", [t.component("src", "Source3", src_conn), t.component("A", "Adder3",
                                                                                  t.adder_connectors("2.0"))],
                    [t.connection("src.y", "A.u1", f'<ssc:LinearTransformation factor="{FACTOR}" offset="{OFFSET}"/>')])
    folder = t.write(tmp_path / "s", t.document(root, "2.0", stop=STOP), {"Source3": src, "Adder3": add})
    r = ipcosim.run(folder, stop_time=STOP, step=H, algorithm=algorithm)
    times = np.arange(round(STOP / H) + 1) * H
    source = np.where(times >= STEP_TIME - 1e-9, AMPLITUDE, 0.0)  # the step, at 0.5 s
    assert np.array_equal(r["src.y"], source)
    assert np.array_equal(r["A.u1"], FACTOR * source + OFFSET)  # the row at t_n: the value exchanged at t_n
    k1, k2, u2 = adder_fmus.K1, adder_fmus.K2, adder_fmus.U2
    if algorithm == "jacobi":  # the step from t_n uses the input recorded at t_n: y at t_n+1 from u1 at t_n
        assert np.array_equal(r["A.y"][1:], k1 * r["A.u1"][:-1] + k2 * u2)
    else:  # the adder steps after the source (direct feedthrough u1 -> y): y at t_n from u1 at t_n
        assert np.array_equal(r["A.y"], k1 * r["A.u1"] + k2 * u2)
