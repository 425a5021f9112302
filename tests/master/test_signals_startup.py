"""A signal that reaches the ``ipcosim`` command while it is still starting (building its parser, which
loads every command module and the named command's options: numpy for a run) ends it as any other
signal does: one line on stderr naming the command and the signal, exit status 128 + signal number.
Under Python's default SIGTERM disposition the process would instead vanish without a word (status
-15) -- what a sweep resumed and stopped at once by a supervisor's ``kill`` showed.

The signal is sent by the command's own process from inside the parser's construction, so it
arrives at exactly that moment on every run.
"""
from __future__ import annotations

import signal
import subprocess
import sys
import textwrap

import pytest

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")

#: The ``ipcosim`` console command, with the signal raised while the parser is being built.
SCRIPT = textwrap.dedent("""
    import os
    import signal
    import sys

    from ipcosim.harness import cli

    build = cli.build_parser

    def build_parser(*args, **kwargs):
        os.kill(os.getpid(), signal.{name})  # arrives while the command modules are being loaded
        return build(*args, **kwargs)

    cli.build_parser = build_parser
    sys.argv = ["ipcosim", "sweep", "pure:single-mass-lqr", "--vary", "plant.Mp=[1]", "--out", {out!r}]
    sys.exit(cli.main())
    """)


@pytest.mark.parametrize("name", ["SIGTERM", "SIGINT"])
def test_a_signal_while_the_command_starts_is_one_line_and_128_plus_its_number(tmp_path, name):
    out = tmp_path / "sweep"
    done = subprocess.run([sys.executable, "-c", SCRIPT.format(name=name, out=str(out))], capture_output=True,
                          text=True, timeout=60)
    number = int(getattr(signal, name))
    assert done.returncode == 128 + number, (done.returncode, done.stderr)
    lines = done.stderr.splitlines()
    # the command is named although its parser was not built yet: it is read from the words given
    assert lines == [f"ipcosim sweep: error: interrupted by {name}; nothing was written"], done.stderr
    assert not out.exists()  # nothing of the sweep was started
