"""The system C compiler, for the two things that compile C: ``ipcosim build --native`` (the native
FMUs, ``ipcosim.harness.native``) and the master's compiled stepping loop (``ipcosim.harness.master.cloop``).
Below every room: it imports nothing of the package."""
from __future__ import annotations

import os
import shutil


def find_compiler() -> str | None:
    """The C compiler to use: ``$CC`` if set (None when it names no program), else the first of
    cc, gcc, clang on PATH; None when there is none."""
    env = os.environ.get("CC")
    if env:
        return shutil.which(env)
    for cc in ("cc", "gcc", "clang"):
        path = shutil.which(cc)
        if path:
            return path
    return None
