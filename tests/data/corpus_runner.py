"""Runs ``ipcosim`` like the console script, counting FMU instances: the bad-input corpus
starts it as a subprocess. Arguments: the command line. Environment: ``CORPUS_COUNTS`` (file
for ``{"instantiated": n, "freed": m}``), ``CORPUS_SIGNAL_AT`` (``PHASE:SIGNAL``, the process
signals itself when the run reaches that phase: load, instantiate, initialize, write,
cleanup; once)."""
from __future__ import annotations

import atexit
import json
import os
import signal
import sys

from ipcosim.harness import cli
from ipcosim.harness.api import engine
from ipcosim.harness.master import results
from ipcosim.harness.master.slave import FMU2Slave, FMUSlave

counts = {"instantiated": 0, "freed": 0}
phase, _, signame = os.environ.get("CORPUS_SIGNAL_AT", "").partition(":")
signum = getattr(signal, signame, None)


fired = []


def _kill(at: str) -> None:
    if at == phase and signum is not None and not fired:
        fired.append(at)
        os.kill(os.getpid(), signum)


def _wrap(owner, name, before=None, after=None):
    real = getattr(owner, name)

    def wrapper(*args, **kwargs):
        if before:
            before()
        out = real(*args, **kwargs)
        if after:
            after()
        return out

    setattr(owner, name, wrapper)


def _instantiated():
    counts["instantiated"] += 1


_free = FMUSlave.free


def _counted_free(self):
    was = self.state
    _kill("cleanup")
    _free(self)
    if was not in ("freed", "created"):
        counts["freed"] += 1


_wrap(engine.Prepared, "_extract", before=lambda: _kill("load"))
_wrap(FMU2Slave, "instantiate", before=lambda: _kill("instantiate"), after=_instantiated)
_wrap(FMU2Slave, "enter_initialization_mode", before=lambda: _kill("initialize"))
_wrap(results.Result, "write_metrics", before=lambda: _kill("write"))
FMUSlave.free = _counted_free


@atexit.register
def _save() -> None:
    path = os.environ.get("CORPUS_COUNTS")
    if path:
        with open(path, "w") as fh:
            json.dump(counts, fh)


sys.exit(cli.main(sys.argv[1:]))
