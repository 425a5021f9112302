"""The system C compiler, for the two things that compile C: ``ipcosim build --native`` (the native
FMUs, ``ipcosim.harness.native``) and the master's compiled stepping loop (``ipcosim.harness.master.cloop``),
and the mingw-w64 cross compiler for the native FMUs' Windows DLLs.
Below every room: it imports nothing of the package."""
from __future__ import annotations

import os
import shutil
import subprocess
import tempfile


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


def run_compiler(cmd: list[str]) -> subprocess.CompletedProcess[str]:
    """Run a compiler command with its temporary files in a folder of its own, removed afterwards.

    An interruption (Ctrl-C, SIGTERM turned into an exception by the command line) asks the
    compiler to stop with SIGTERM, so it removes its own files, and then removes the folder:
    nothing is left in the temporary folder.
    """
    with tempfile.TemporaryDirectory(prefix="ipcosim-cc-") as scratch:
        env = {**os.environ, "TMPDIR": scratch, "TMP": scratch, "TEMP": scratch}
        with subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                              start_new_session=os.name == "posix") as proc:
            try:
                out, err = proc.communicate()
            except BaseException:
                _stop_group(proc)
                raise
        return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


def _stop_group(proc: subprocess.Popen[str]) -> None:
    """SIGTERM to the compiler and the programs it started (its own process group), SIGKILL after 2 s."""
    import signal

    def send(sig: int) -> None:
        try:
            os.killpg(proc.pid, sig) if os.name == "posix" else proc.terminate()
        except OSError:
            pass

    send(signal.SIGTERM)
    try:
        proc.wait(timeout=2.0)
    except subprocess.TimeoutExpired:
        send(getattr(signal, "SIGKILL", signal.SIGTERM))
        proc.wait()
