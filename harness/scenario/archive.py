"""Safe extraction of zip archives (``.ssp`` scenarios and the ``.fmu`` files they carry).

Every member name is checked before a byte is written: absolute names, drive letters,
backslashes, ``..`` components, symbolic links and device or other special entries are
refused, and so is any name whose resolved path would leave the target folder (also through
a link already present there). The archive's member count and total uncompressed size are
bounded, and each member's size is checked while it is copied (a member that lies about
its size in the directory cannot get past the bound). A refusal is one line naming the
archive and the member.
"""
from __future__ import annotations

import os
import stat
import zipfile
from pathlib import Path, PurePosixPath
from typing import Iterable

from ipcosim.errors import IpcosimError

#: At most this many members in one archive.
MAX_MEMBERS = 10_000
#: At most this many bytes extracted from one archive (uncompressed).
MAX_TOTAL_BYTES = 2 * 1024 ** 3


class UnsafeArchiveError(IpcosimError, ValueError):
    """An archive member that would be written outside the target folder, a link, a device,
    or an archive beyond the size and count limits."""


def _display(path: Path) -> str:
    try:
        return os.path.relpath(path)
    except ValueError:
        return str(path)


def member_path(archive: Path, name: str, target: Path, root: Path | None = None) -> Path:
    """The path inside ``target`` where member ``name`` goes.

    Parameters
    ----------
    archive : Path
        The archive (named in messages).
    name : str
        The member's name.
    target : Path
        The extraction folder.
    root : Path, optional
        ``target.resolve()``, given by a caller that checks every member of an archive (resolved once).

    Raises
    ------
    UnsafeArchiveError
        If the name is absolute, has a drive letter, a backslash or a ``..`` component, or
        resolves (following links already in ``target``) outside ``target``.
    """
    where = lambda: f"{_display(archive)}: member {name!r}"
    if not name or "\x00" in name:
        raise UnsafeArchiveError(f"{where()}: empty or NUL in the name")
    if name.startswith(("/", "\\")) or "\\" in name or (len(name) > 1 and name[1] == ":"):
        raise UnsafeArchiveError(f"{where()}: absolute name or drive letter (refused)")
    parts = PurePosixPath(name).parts
    if any(p == ".." for p in parts):
        raise UnsafeArchiveError(f"{where()}: '..' in the name would leave the extraction folder (refused)")
    root = target.resolve() if root is None else root
    dest = target.joinpath(*[p for p in parts if p not in ("", ".")])
    resolved = dest.resolve()
    if resolved != root and root not in resolved.parents:
        raise UnsafeArchiveError(f"{where()}: resolves outside the extraction folder (refused)")
    return dest


def _check_entry(archive: Path, info: zipfile.ZipInfo) -> None:
    mode = info.external_attr >> 16
    if info.create_system == 3 and mode:  # Unix attributes present
        kind = stat.S_IFMT(mode)
        if stat.S_ISLNK(mode):
            raise UnsafeArchiveError(f"{_display(archive)}: member {info.filename!r}: symbolic link (refused)")
        if kind and not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
            raise UnsafeArchiveError(f"{_display(archive)}: member {info.filename!r}: device or special file "
                                     f"(refused)")


def check_archive(archive: Path, zf: zipfile.ZipFile) -> list[zipfile.ZipInfo]:
    """Every member of ``zf`` after the count, size and entry-type checks (not the names)."""
    infos = zf.infolist()
    if len(infos) > MAX_MEMBERS:
        raise UnsafeArchiveError(f"{_display(archive)}: {len(infos)} members, more than the limit {MAX_MEMBERS}")
    total = sum(i.file_size for i in infos)
    if total > MAX_TOTAL_BYTES:
        raise UnsafeArchiveError(f"{_display(archive)}: {total} bytes uncompressed, more than the limit "
                                 f"{MAX_TOTAL_BYTES}")
    for info in infos:
        _check_entry(archive, info)
    return infos


def _copy(archive: Path, zf: zipfile.ZipFile, info: zipfile.ZipInfo, dest: Path, budget: list[int]) -> None:
    dest.parent.mkdir(parents=True, exist_ok=True)
    with zf.open(info) as src, open(dest, "xb") as dst:
        while True:
            chunk = src.read(1 << 20)
            if not chunk:
                break
            budget[0] -= len(chunk)
            if budget[0] < 0:
                raise UnsafeArchiveError(f"{_display(archive)}: member {info.filename!r}: more than "
                                         f"{MAX_TOTAL_BYTES} bytes uncompressed in the archive")
            dst.write(chunk)


def safe_extract(archive: str | os.PathLike[str], target: str | os.PathLike[str],
                 members: Iterable[str] | None = None) -> Path:
    """Extract ``members`` (default: all) of the zip ``archive`` into the folder ``target``.

    Parameters
    ----------
    archive : path
        The zip file (``.ssp``, ``.fmu``).
    target : path
        The folder to extract into (created).
    members : iterable of str, optional
        Member names to extract; every name of the archive by default. A member that
        already exists in ``target`` is left as it is.

    Returns
    -------
    Path
        ``target``.

    Raises
    ------
    UnsafeArchiveError
        For an unsafe member (see :func:`member_path`), a link or device, or an archive
        beyond :data:`MAX_MEMBERS` / :data:`MAX_TOTAL_BYTES`; nothing is written then
        unless the failure is found while copying (a member larger than declared).
    """
    archive, target = Path(archive), Path(target)
    target.mkdir(parents=True, exist_ok=True)
    try:
        zf = zipfile.ZipFile(archive)
    except (zipfile.BadZipFile, OSError) as exc:
        raise UnsafeArchiveError(f"{_display(archive)}: not a zip archive ({exc})") from None
    with zf:
        infos = {i.filename: i for i in check_archive(archive, zf)}
        names = list(infos) if members is None else list(members)
        plan = []
        root = target.resolve()
        for name in names:  # check every name before writing anything
            dest = member_path(archive, name, target, root)
            if name not in infos:
                raise UnsafeArchiveError(f"{_display(archive)}: member {name!r}: no such member")
            plan.append((infos[name], dest))
        budget = [MAX_TOTAL_BYTES]
        for info, dest in plan:
            if info.is_dir():
                dest.mkdir(parents=True, exist_ok=True)
            elif not dest.exists():
                _copy(archive, zf, info, dest, budget)
    return target
