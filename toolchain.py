"""The system C compiler, for the two things that compile C: ``ipcosim build --native`` (the native
FMUs, ``ipcosim.harness.native``) and the master's compiled stepping loop (``ipcosim.harness.master.cloop``),
and the mingw-w64 cross compiler for the native FMUs' Windows DLLs.
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


#: Debian's mingw-w64 cross compiler for 64-bit Windows (package gcc-mingw-w64-x86-64).
CROSS_COMPILER = "x86_64-w64-mingw32-gcc"


def find_cross_compiler() -> str | None:
    """The compiler of Windows x86-64 DLLs: ``$MINGW_CC`` if set (None when it names no program),
    else ``x86_64-w64-mingw32-gcc`` on PATH; None when there is none."""
    env = os.environ.get("MINGW_CC")
    if env:
        return shutil.which(env)
    return shutil.which(CROSS_COMPILER)
