"""The system C compiler, for the two things that compile C: ``ipcosim build --native`` (the native
FMUs, ``ipcosim.harness.native``) and the master's compiled stepping loop (``ipcosim.harness.master.cloop``),
and the cross compilers of the native FMUs' other platforms (mingw-w64 for the Windows DLLs, Debian's
aarch64 GNU/Linux compiler for the 64-bit ARM libraries).
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


#: The cross compiler of each further platform of the native FMUs: (environment variable naming
#: another, Debian's program, the Debian package that installs it).
CROSS_COMPILERS = {"win64": ("MINGW_CC", "x86_64-w64-mingw32-gcc", "gcc-mingw-w64-x86-64"),
                   "aarch64": ("AARCH64_CC", "aarch64-linux-gnu-gcc", "gcc-aarch64-linux-gnu")}


def find_cross_compiler(platform: str = "win64") -> str | None:
    """The cross compiler for ``platform`` (``win64``: Windows x86-64 DLLs, ``aarch64``: 64-bit ARM
    Linux libraries): the program its environment variable names if set (``$MINGW_CC``,
    ``$AARCH64_CC``; None when it names no program), else Debian's compiler on PATH; None when
    there is none."""
    variable, program, _ = CROSS_COMPILERS[platform]
    env = os.environ.get(variable)
    if env:
        return shutil.which(env)
    return shutil.which(program)


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
