"""A signal under the command line's handling (``signals.deferred(immediate=True)``) stops the
command, but never inside a compiled module's initialization and never where Python cannot raise it.

Each case runs in a process of its own (the signal handlers are the process's), which sends
itself the signal at the moment under test and prints what it saw as JSON. The compiled module
is the standard library's ``_decimal``: its initialization calls ``numbers.Number.register``
(Python code), which the child replaces by one that sends the signal from inside it.
"""
from __future__ import annotations

import importlib.machinery
import importlib.util
import json
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")

CHILD_S = 20.0  # a child that never sees its signal hangs to this limit

_DECIMAL = importlib.util.find_spec("_decimal")
compiled_decimal = pytest.mark.skipif(
    _DECIMAL is None or not isinstance(_DECIMAL.loader, importlib.machinery.ExtensionFileLoader),
    reason="this Python's _decimal is not a compiled module loaded from a file")

#: Makes ``_decimal``'s initialization send ``{sig}`` from inside it (its first call of
#: ``numbers.Number.register``), then run Python code for ``{busy_s}`` s (where a handler runs).
IN_DECIMAL_INIT = textwrap.dedent("""
    import numbers
    def register(cls, *more):
        if not getattr(register, "sent", False):
            register.sent = True
            os.kill(os.getpid(), signal.{sig})
            end = time.monotonic() + {busy_s}
            while time.monotonic() < end:
                time.sleep(0.005)
        return cls
    numbers.Number.register = staticmethod(register)
""")


def _child(tmp_path: Path, body: str, setup: str = "", modules: dict[str, str] | None = None) -> dict:
    for name, text in (modules or {}).items():
        (tmp_path / f"{name}.py").write_text(textwrap.dedent(text))
    script = textwrap.dedent("""
        import json, os, signal, sys, time
        sys.path.insert(0, {folder!r})
        from ipcosim.harness.master import signals
        {setup}
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
    """).format(folder=str(tmp_path), setup=textwrap.dedent(setup),
                body=textwrap.indent(textwrap.dedent(body), " " * 8))
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=CHILD_S)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1]) | {"stderr": proc.stderr}


@compiled_decimal
@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_a_signal_during_a_compiled_modules_initialization_is_raised_once_it_is_loaded(tmp_path, sig):
    seen = _child(tmp_path, """
        assert "_decimal" not in sys.modules
        import _decimal
        seen["loaded"] = hasattr(_decimal, "Decimal") and "_decimal" in sys.modules
        end = time.monotonic() + 10
        while time.monotonic() < end:
            time.sleep(0.005)
    """, setup=IN_DECIMAL_INIT.format(sig=sig, busy_s=0.1))
    assert seen.get("error") is None, seen
    assert seen.get("loaded") is True, seen  # the initialization was not cut short
    assert seen["interrupted"] == getattr(signal, sig), seen


@compiled_decimal
def test_a_second_signal_during_a_compiled_modules_initialization_still_forces_the_exit(tmp_path):
    setup = IN_DECIMAL_INIT.format(sig="SIGTERM", busy_s=0.05) + textwrap.dedent("""
        first = numbers.Number.register
        def stuck(cls, *more):
            first(cls)
            os.kill(os.getpid(), signal.SIGTERM)  # a user's second signal: the initialization never ends
            while True:
                time.sleep(0.005)
        numbers.Number.register = staticmethod(stuck)
    """)
    script = textwrap.dedent("""
        import os, signal, sys, time
        from ipcosim.harness.master import signals
    """) + textwrap.dedent(setup) + textwrap.dedent("""
        with signals.deferred(immediate=True):
            import _decimal
    """)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=CHILD_S)
    assert proc.returncode == 128 + signal.SIGTERM, proc.stderr
    assert "second signal" in proc.stderr, proc.stderr


def test_a_signal_during_a_python_modules_import_stops_the_command_there(tmp_path):
    # nothing compiled is being initialized: the signal is raised at once, the module left unloaded
    seen = _child(tmp_path, """
        import half_way
    """, modules={"half_way": """
        import os, signal, time
        os.kill(os.getpid(), signal.SIGTERM)
        end = time.monotonic() + 10
        while time.monotonic() < end:
            time.sleep(0.005)
    """})
    assert seen["interrupted"] == signal.SIGTERM, seen


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
        end = time.monotonic() + 10
        while time.monotonic() < end:
            time.sleep(0.005)
    """)
    assert seen.get("error") is None, seen
    assert seen["interrupted"] == signal.SIGINT and seen["went_on"] is True, seen
    assert "Exception ignored" not in seen["stderr"], seen["stderr"]


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
