"""A signal under the command line's handling (``signals.deferred(immediate=True)``) stops the
command, but never inside an import and never where Python cannot raise it.

Each case runs in a process of its own (the signal handlers are the process's), which sends
itself the signal at the moment under test and prints what it saw as JSON.
"""
from __future__ import annotations

import json
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")

CHILD_S = 20.0  # a child that never sees its signal hangs to this limit


def _child(tmp_path: Path, body: str, modules: dict[str, str] | None = None) -> dict:
    for name, text in (modules or {}).items():
        (tmp_path / f"{name}.py").write_text(textwrap.dedent(text))
    script = textwrap.dedent("""
        import json, os, signal, sys, time
        sys.path.insert(0, {folder!r})
        from ipcosim.harness.master import signals
        seen = {{}}
        with signals.deferred(immediate=True):
            try:
        {body}
                seen["interrupted"] = None
            except signals.Interrupted as exc:
                seen["interrupted"] = exc.signum
            except Exception as exc:
                seen["error"] = f"{{type(exc).__name__}}: {{exc}}"
        print(json.dumps(seen))
    """).format(folder=str(tmp_path), body=textwrap.indent(textwrap.dedent(body), " " * 8))
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=CHILD_S)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1]) | {"stderr": proc.stderr}


def test_a_signal_during_an_import_is_raised_once_the_module_is_loaded_whole(tmp_path):
    # the module sends the signal half-way through its own code, then goes on being loaded
    seen = _child(tmp_path, """
        import half_way
        seen["loaded"] = getattr(sys.modules.get("half_way"), "END", False)
        while True:
            time.sleep(0.005)
    """, {"half_way": """
        import os, signal, time
        os.kill(os.getpid(), signal.SIGTERM)
        for _ in range(20):  # Python code runs here: the signal's handler is called in it
            time.sleep(0.005)
        END = True
    """})
    assert seen.get("error") is None, seen
    assert seen["interrupted"] == signal.SIGTERM, seen
    assert seen["loaded"] is True, seen  # the import was not cut short: the module is whole, and in sys.modules


def test_a_command_run_from_a_modules_own_import_still_stops(tmp_path):
    # the handling begins inside an import: only imports begun after it hold the signal back
    (tmp_path / "runs_at_import.py").write_text(textwrap.dedent("""
        import os, signal, time
        from ipcosim.harness.master import signals
        with signals.deferred(immediate=True):
            try:
                os.kill(os.getpid(), signal.SIGTERM)
                for _ in range(400):  # 2 s: the signal is raised in here, not once this import is over
                    time.sleep(0.005)
                RAISED = False
            except signals.Interrupted as exc:
                RAISED = exc.signum
    """))
    script = f"import sys; sys.path.insert(0, {str(tmp_path)!r}); import runs_at_import; print(runs_at_import.RAISED)"
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=CHILD_S)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == str(int(signal.SIGTERM)), proc.stdout


def test_a_library_that_turns_an_import_failure_into_its_own_error_never_sees_the_signal(tmp_path):
    # what a compiled extension's initialization does with any exception: ImportError from it
    seen = _child(tmp_path, """
        import wrapper
        seen["loaded"] = wrapper.END
        while True:
            time.sleep(0.005)
    """, {"wrapper": """
        try:
            import inner
        except BaseException as exc:
            raise ImportError("initialization failed") from exc
        END = True
    """, "inner": """
        import os, signal, time
        os.kill(os.getpid(), signal.SIGINT)
        for _ in range(20):
            time.sleep(0.005)
    """})
    assert seen.get("error") is None, seen
    assert seen["interrupted"] == signal.SIGINT and seen["loaded"] is True, seen


def test_a_signal_python_could_not_raise_is_delivered_again(tmp_path):
    # met inside a __del__, the exception is reported as ignored and lost; the command must still stop
    seen = _child(tmp_path, """
        class Finalized:
            def __del__(self):
                os.kill(os.getpid(), signal.SIGINT)
                for _ in range(20):
                    time.sleep(0.005)
        Finalized()
        seen["went_on"] = True
        while True:
            time.sleep(0.005)
    """)
    assert seen.get("error") is None, seen
    assert seen["interrupted"] == signal.SIGINT and seen["went_on"] is True, seen
    assert "Exception ignored" not in seen["stderr"], seen["stderr"]


def test_a_second_signal_during_an_import_still_forces_the_exit(tmp_path):
    script = textwrap.dedent(f"""
        import sys
        sys.path.insert(0, {str(tmp_path)!r})
        from ipcosim.harness.master import signals
        with signals.deferred(immediate=True):
            import stuck
    """)
    (tmp_path / "stuck.py").write_text(textwrap.dedent("""
        import os, signal, time
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(0.05)
        os.kill(os.getpid(), signal.SIGTERM)  # a user's second signal: the import never ends
        while True:
            time.sleep(0.005)
    """))
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=CHILD_S)
    assert proc.returncode == 128 + signal.SIGTERM, proc.stderr
    assert "second signal" in proc.stderr, proc.stderr


def test_the_command_line_reports_a_signal_a_library_turned_into_its_own_error():
    from ipcosim.harness.cli import _interruption_behind
    from ipcosim.harness.master.signals import Interrupted

    try:
        try:
            raise Interrupted(signal.SIGINT)
        except Interrupted as exc:
            raise ImportError("initialization failed") from exc
    except ImportError as exc:
        wrapped = exc
    try:
        try:
            raise Interrupted(signal.SIGTERM)
        except Interrupted:
            raise RuntimeError("while cleaning up") from None  # context kept, though not shown
    except RuntimeError as exc:
        suppressed = exc
    assert isinstance(_interruption_behind(wrapped), Interrupted)
    assert _interruption_behind(wrapped).signum == signal.SIGINT
    assert _interruption_behind(suppressed).signum == signal.SIGTERM
    assert _interruption_behind(ImportError("initialization failed")) is None
