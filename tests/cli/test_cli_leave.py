"""The ``ipcosim`` command leaves after a run without the interpreter's teardown (``cli.leave``): what it printed
and wrote is all there, its exit handlers ran, and its status is the command's."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

#: ``leave`` in a fresh interpreter: an exit handler writing a file, text left in the block-buffered stdout of a
#: pipe, and (with an argument) a thread that is no daemon still running.
PROBE = r"""
import atexit, sys, threading, pathlib
from ipcosim.harness.cli import leave
atexit.register(pathlib.Path(sys.argv[1]).write_text, "exit handlers ran")
if len(sys.argv) > 2:
    stop = threading.Event()
    threading.Thread(target=stop.wait).start()
    threading.Timer(0.2, stop.set).start()
print("x" * 5000, end="")  # below the pipe buffer's size: sits in stdout's buffer
leave(7)
print("teardown")
sys.exit(0)
"""


def _probe(tmp_path: Path, *extra: str) -> tuple[subprocess.CompletedProcess[str], Path]:
    marker = tmp_path / "marker.txt"
    done = subprocess.run([sys.executable, "-c", PROBE, str(marker), *extra], capture_output=True, text=True,
                          timeout=60)
    return done, marker


def test_leave_flushes_runs_the_exit_handlers_and_keeps_the_status(tmp_path: Path) -> None:
    done, marker = _probe(tmp_path)
    assert done.returncode == 7, done.stderr
    assert done.stdout == "x" * 5000  # flushed, and nothing after leave ran
    assert marker.read_text() == "exit handlers ran"


def test_leave_gives_way_to_a_running_thread(tmp_path: Path) -> None:
    """A thread that is no daemon would be cut off: the normal exit then waits for it instead."""
    done, marker = _probe(tmp_path, "thread")
    assert done.returncode == 0, done.stderr
    assert done.stdout == "x" * 5000 + "teardown\n"
    assert marker.read_text() == "exit handlers ran"


def test_the_run_command_writes_everything_before_it_leaves(tmp_path: Path) -> None:
    """The console command itself (``leave`` runs in its process only): its summary and its files whole."""
    exe = Path(sys.executable).with_name("ipcosim")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "ipcosim.harness.cli"]
    out = tmp_path / "out"
    done = subprocess.run([*cmd, "run", "single-mass-lqr", "--stop-time", "0.2", "--out", str(out)],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.rstrip().splitlines()[-1].startswith("results: ")
    rows = (out / "results.csv").read_text().splitlines()
    assert rows[0].startswith("time,") and len(rows) == 1 + 201 and float(rows[-1].split(",")[0]) == 0.2
    assert (out / "metrics.json").read_text().rstrip().endswith("}")


#: The console ``ipcosim run`` (``argv`` None) in a fresh interpreter, the collector's state seen where the run is
#: prepared and where it steps, printed before the command leaves; then ``main`` called from Python.
COLLECTOR_PROBE = r"""
import gc, sys
import ipcosim.harness.api.engine as engine
seen = {}
def spy(name, real):
    def call(*args, **kwargs):
        seen[name] = (gc.isenabled(), gc.get_freeze_count() > 0)
        return real(*args, **kwargs)
    return call
engine.prepare_with, engine.run_with = spy("prepare", engine.prepare_with), spy("run", engine.run_with)
from ipcosim.harness.cli import main
argv = ["run", "single-mass-lqr", "--stop-time", "0.05", "--quiet", "--out", sys.argv[1]]
if sys.argv[2] == "python":
    main(argv)
    print(seen, gc.isenabled(), gc.get_freeze_count())
else:
    import atexit
    atexit.register(lambda: print(seen))  # leave runs the exit handlers
    sys.argv[1:] = argv
    main()
"""


def test_the_run_command_collects_garbage_while_it_runs_not_while_it_starts(tmp_path: Path) -> None:
    """The console run starts with the cyclic collector off and steps with it on, past what its start made;
    ``main`` called from Python leaves the collector as it found it."""
    done = subprocess.run([sys.executable, "-c", COLLECTOR_PROBE, str(tmp_path / "a"), "console"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["{'prepare':", "(False,", "False),", "'run':", "(True,", "True)}"]
    done = subprocess.run([sys.executable, "-c", COLLECTOR_PROBE, str(tmp_path / "b"), "python"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["{'prepare':", "(True,", "False),", "'run':", "(True,", "False)}", "True", "0"]
