"""How many threads the numerical libraries (OpenBLAS, OpenMP, MKL) start in an ipcosim process.

ipcosim's matrices are small (at most a dozen states), so a BLAS thread pool brings nothing but a
worker that spins while the main thread works: measured on a 2-core machine, a cold
``ipcosim run`` of a Python-FMU scenario spends about 0.08 s of CPU more with OpenBLAS's default
pool than with one thread, and an FMU's initialization twice its CPU time. The command line and
the sweep's worker processes therefore ask for one thread, unless the user has set a count.
"""
from __future__ import annotations

import os

__all__ = ["SINGLE_THREAD_ENV", "single_threaded"]

#: Thread-count variables of the BLAS/OpenMP libraries.
SINGLE_THREAD_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def single_threaded(env: "os._Environ[str] | dict[str, str]" = os.environ) -> None:
    """Set each of :data:`SINGLE_THREAD_ENV` to 1 in ``env`` where the user has not set it.

    A library reads its variable when it is loaded: call this before numpy is imported for it to
    take effect in this process; processes started afterwards inherit it.

    Examples
    --------
    >>> env = {"OMP_NUM_THREADS": "4"}
    >>> single_threaded(env)
    >>> env["OMP_NUM_THREADS"], env["OPENBLAS_NUM_THREADS"]
    ('4', '1')
    """
    for name in SINGLE_THREAD_ENV:
        env.setdefault(name, "1")
