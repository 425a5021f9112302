"""One BLAS thread per ipcosim command unless the user asks for more (ipcosim.harness.support.threads)."""
from __future__ import annotations

import os
import subprocess
import sys

from ipcosim.harness.support.threads import SINGLE_THREAD_ENV, single_threaded

PROBE = ("import contextlib, io, os, sys; from ipcosim.harness.cli import main\n"
         "assert 'numpy' not in sys.modules, 'numpy loaded before the thread count is set'\n"
         "with contextlib.redirect_stdout(io.StringIO()): status = main(['list'])\n"
         "print(status, *(os.environ.get(n, '-') for n in %r))" % (SINGLE_THREAD_ENV,))


def test_single_threaded_fills_only_what_the_user_left_unset() -> None:
    env = {"OPENBLAS_NUM_THREADS": "3"}
    single_threaded(env)
    assert env == {"OPENBLAS_NUM_THREADS": "3", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def _probe(**extra: str) -> list[str]:
    env = {k: v for k, v in os.environ.items() if k not in SINGLE_THREAD_ENV}
    env.update(extra)
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, check=True)
    return out.stdout.split()


def test_the_command_line_asks_for_one_thread_before_numpy_loads() -> None:
    assert _probe() == ["0", "1", "1", "1"]
    assert _probe(OMP_NUM_THREADS="2") == ["0", "2", "1", "1"]
