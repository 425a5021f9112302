"""How to rebuild an FMU of the project's own build folders that is older than the sources: the
command for a folder, and the hint an error about a missing variable or parameter ends with."""
from __future__ import annotations

from pathlib import Path

from ipcosim.harness.master.system import Model


def rebuild_command(folder: Path) -> str | None:
    """The command that rebuilds ``folder`` if it is one of the project's build folders, else None."""
    from ipcosim.harness.native.cbuild import OUT_DIRS
    from ipcosim.harness.support.paths import BUILD_DIR

    folder = folder.resolve()
    if not folder.is_relative_to(Path(BUILD_DIR).resolve()):
        return None
    fmi = {d: v for v, d in OUT_DIRS.items()}.get(folder.name)
    return "ipcosim build" + ("" if fmi is None else " --native" + ("" if fmi == "2" else f" --fmi {fmi}"))


def rebuild_hint(model: Model) -> str:
    """How to rebuild an FMU of the project's own build folder that is older than the sources (a checkout
    updated since ``ipcosim build``), from the folder's build cache (``ipcosim.fmus.pybuild.is_stale``); where
    the cache does not say (the native folders), that it may be. "" for an FMU that is current or from
    anywhere else."""
    from ipcosim.fmus.pybuild import is_stale

    command = rebuild_command(model.path.parent) if model.path else None
    if command is None:
        return ""
    stale = is_stale(model.path)
    if stale is False:
        return ""
    verb = "is" if stale else "may be"
    return f"; {model.path.resolve().parent} {verb} older than the sources: `{command}` rebuilds it"
