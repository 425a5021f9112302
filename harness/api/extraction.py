"""Where a prepared scenario's FMUs are extracted and what of them: an ``.ssp`` archive's FMUs taken out
(:func:`archive_members`), each FMU checked for a shared library for this platform (:func:`check_binary`)
and extracted with only the members a run reads (:func:`runtime_members`), into a temporary folder per
process (:data:`EXTRACT_PREFIX`) removed when the scenario is closed and, after a process killed before
it could, by the next run (:func:`remove_stale_extractions`).
"""
from __future__ import annotations

import os
import shutil
import tempfile
import zipfile
from pathlib import Path
from typing import Any

from ipcosim.errors import IpcosimError
from ipcosim.harness.master import signals
from ipcosim.harness.scenario.archive import member_path, safe_extract
from ipcosim.harness.scenario.structure import Scenario


class NoBinaryError(IpcosimError, OSError):
    """An FMU without a shared library for this machine's platform."""


def binary_folders(fmi_version: str) -> tuple[str, ...]:
    """The ``binaries/`` folders an FMU's shared library for this machine may be in: FMI 2.0's
    platform name (``linux64``; off x86 also FMI 3.0's tuple, as FMI 2.0.4 section 2.3 allows),
    FMI 3.0's platform tuple (``x86_64-linux``)."""
    import fmpy

    if fmi_version.startswith("3"):
        return (fmpy.platform_tuple,)
    if fmpy.architecture in ("x86", "x86_64"):
        return (fmpy.platform,)
    return (fmpy.platform, fmpy.platform_tuple)


def check_binary(fmu: Path, model: Any, where: str) -> None:
    """Refuse, in one line naming ``where``, an FMU whose archive holds no shared library for this
    platform (``binaries/<platform>/<modelIdentifier>.<ext>``), listing the platforms it has.

    Raises
    ------
    NoBinaryError
    """
    import fmpy

    if not zipfile.is_zipfile(fmu):
        return  # an extracted folder or a non-archive: fmpy reports what it lacks
    with zipfile.ZipFile(fmu) as zf:
        names = [n.replace("\\", "/") for n in zf.namelist()]
    folders = binary_folders(model.fmi_version)
    library = f"{model.model_identifier}{fmpy.sharedLibraryExtension}"
    if any(f"binaries/{folder}/{library}" in names for folder in folders):
        return
    parts = [n.split("/") for n in names]
    has = sorted({p[1] for p in parts if len(p) >= 3 and p[0] == "binaries" and p[1] and p[-1]})  # with a file
    raise NoBinaryError(f"{where}: has no binary for {folders[0]} (it has: {', '.join(has) or 'none'})")


def runtime_members(fmu: Path, model: Any, target: Path) -> list[str] | None:
    """The members of an FMU archive a run reads: ``modelDescription.xml``, ``resources/`` and the
    shared libraries of this platform (:func:`binary_folders`); not the sources, the documentation
    nor other platforms' binaries (a native FMU carries them: writing them and removing them again
    was most of a run's extraction). Every member's name is checked as extracting it would be
    (:func:`~ipcosim.harness.scenario.archive.member_path`, into ``target``). None (every member)
    for what is not a zip archive.

    Raises
    ------
    UnsafeArchiveError
        A member whose name would leave ``target``.
    """
    if not zipfile.is_zipfile(fmu):
        return None
    folders = tuple(f"binaries/{folder}/" for folder in binary_folders(model.fmi_version))
    with zipfile.ZipFile(fmu) as zf:
        names = zf.namelist()
    root = target.resolve()
    for name in names:
        member_path(fmu, name, target, root)
    return [n for n in names if n == "modelDescription.xml" or n.startswith(("resources/", *folders))]


#: Name of a run's temporary extraction folder, followed by the owning process's id: ``ipcosim-run-<pid>-*``.
EXTRACT_PREFIX = "ipcosim-run-"


def remove_stale_extractions(root: str | os.PathLike[str] | None = None) -> list[Path]:
    """Remove the extraction folders (:data:`EXTRACT_PREFIX`) in ``root`` (default: the temporary
    folder) whose owning process is gone -- a run killed before it could clean up -- and that
    belong to this user; folders of running processes are left alone.

    Returns
    -------
    list of Path
        The folders removed.
    """
    removed = []
    for folder in Path(root or tempfile.gettempdir()).glob(f"{EXTRACT_PREFIX}*-*"):
        pid = folder.name[len(EXTRACT_PREFIX):].split("-", 1)[0]
        try:
            mine = folder.is_dir() and folder.stat().st_uid == os.getuid()
        except (OSError, AttributeError):  # gone meanwhile; no uids on this OS
            continue
        if mine and pid.isdigit() and int(pid) != os.getpid() and not _alive(int(pid)):
            shutil.rmtree(folder, ignore_errors=True)
            removed.append(folder)
    return removed


def _alive(pid: int) -> bool:
    """Whether process ``pid`` exists (True where that cannot be asked safely)."""
    if os.name == "nt":  # os.kill(pid, 0) would send it CTRL_C_EVENT there
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # exists, someone else's
        return True
    return True


def remove_temp(path: str) -> None:
    """Remove a temporary extraction folder and forget it (a forced exit no longer removes it)."""
    shutil.rmtree(path, ignore_errors=True)
    signals.unregister_temp(path)


def archive_members(scenario: Scenario, work: Path) -> dict[str, Path]:
    """Extract the FMUs an ``.ssp`` archive carries (safely, see
    :mod:`ipcosim.harness.scenario.archive`); components whose FMU is missing are left out."""
    out: dict[str, Path] = {}
    with zipfile.ZipFile(scenario.location) as zf:
        names = set(zf.namelist())
    wanted = {}
    for comp in scenario.components:
        if comp.source.startswith("file:"):
            continue
        member_path(scenario.location, comp.source, work / "ssp")  # refuses '..', absolute names
        if comp.source in names:
            wanted[comp.name] = comp.source
    safe_extract(scenario.location, work / "ssp", sorted(set(wanted.values())))
    for comp_name, member in wanted.items():
        out[comp_name] = member_path(scenario.location, member, work / "ssp")
    return out
