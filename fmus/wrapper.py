"""pythonfmu's C++ wrapper binary: the pinned version, and the one-instruction fix every FMU build applies.

Every ipcosim FMU runs inside pythonfmu 0.7.0's FMI wrapper (``binaries/linux64/<Model>.so``,
a copy of ``pythonfmu/resources/binaries/linux64/libpythonfmu-export.so``). That binary keeps
its interpreter guard (``PyState``) in a static ``std::shared_ptr`` and resets the same
pointer again from a library destructor (``__attribute__((destructor)) onLibraryUnload ->
finalizePythonInterpreter: pyState = nullptr``). When a process exits, glibc runs the C++
static destructors (``__cxa_atexit``) *before* the ELF destructors (``_dl_fini``), so
``finalizePythonInterpreter`` releases a ``shared_ptr`` that was already destroyed: it
decrements the use count inside the freed control block and, when the freed memory still
reads 1, destroys the ``PyState`` and frees the block a second time. That double free
corrupts the heap of every host that loaded one of these FMUs, whichever host it is; the
abort follows later at whatever free meets the damage (``corrupted double-linked list`` in
libgfortran's exit handler, or inside ``Py_FinalizeEx``). Valgrind names it on every exit::

    Invalid read of size 4
       at finalizePythonInterpreter (in .../binaries/linux64/Setpoint.so)
       by _dl_call_fini / _dl_fini / __run_exit_handlers / exit
     Address ... is 8 bytes inside a block of size 128 free'd
       at operator delete / __run_exit_handlers / exit
     Block was alloc'd at operator new / pythonfmu::createInstance / fmi2Instantiate

The fix (:func:`patch_binary`): ``finalizePythonInterpreter`` returns at once (its first
instruction after ``endbr64`` becomes ``ret``). The static destructor alone then releases
the ``PyState`` exactly once at exit. Nothing is lost: the library carries GNU-unique
symbols, so the dynamic loader never unloads it (``dlclose`` is a no-op) and the destructor
path only ever ran at exit. Where the wrapper initialized Python itself (a host that is not
Python), that single release still finalizes the interpreter at exit, on the wrapper's own
thread, as pythonfmu intends.

The patch is applied to the exact binary of pythonfmu 0.7.0 only (SHA-256 checked before and
after); any other pythonfmu fails the build with one line naming the pinned version.
"""
from __future__ import annotations

import hashlib
import struct
import zipfile
from pathlib import Path

import pythonfmu

__all__ = ["PINNED_VERSION", "PATCH_ID", "WrapperError", "check_pythonfmu", "patch_binary", "patch_fmu"]

#: The pythonfmu release whose wrapper binary the patch and the glue in ``ipcosim.fmus.fmi`` answer.
PINNED_VERSION = "0.7.0"
#: Names the patch in the build stamp, so FMUs built before (or after) a change of it are rebuilt.
PATCH_ID = "finalizePythonInterpreter-ret-1"
_SYMBOL = b"finalizePythonInterpreter"
_ORIGINAL_SHA256 = "4be156a552c16f30eb4395805c59855d8d4086056d0f165442565f6c5fbac0c9"
_PATCHED_SHA256 = "808689806994c9ac5b7ce4b0ffb1bb801cb50b5718e7d93bfc3d1131feabd2c9"
_ENDBR64 = bytes.fromhex("f30f1efa")
_PUSH_RBP = 0x55
_RET = 0xC3


class WrapperError(RuntimeError):
    """pythonfmu or its wrapper binary is not the pinned one the FMU runtime relies on."""


def check_pythonfmu() -> Path:
    """Check that the installed pythonfmu is the pinned release; return its linux64 wrapper binary.

    Raises
    ------
    WrapperError
        Naming the installed and the pinned version.
    """
    version = getattr(pythonfmu, "__version__", "?")
    if version != PINNED_VERSION:
        raise WrapperError(f"pythonfmu {version} is installed; ipcosim FMUs need pythonfmu=={PINNED_VERSION} "
                           "(its wrapper binary is patched and its behaviour relied on)")
    return Path(pythonfmu.__file__).parent / "resources" / "binaries" / "linux64" / "libpythonfmu-export.so"


def _symbol_offset(elf: bytes, name: bytes) -> int:
    """File offset of the defined dynamic symbol ``name`` in an ELF64 little-endian shared object."""
    if elf[:4] != b"\x7fELF" or elf[4] != 2 or elf[5] != 1:
        raise WrapperError("wrapper binary: not an ELF64 little-endian file")
    shoff, = struct.unpack_from("<Q", elf, 0x28)
    shentsize, shnum = struct.unpack_from("<HH", elf, 0x3A)
    sections = [struct.unpack_from("<IIQQQQIIQQ", elf, shoff + k * shentsize) for k in range(shnum)]
    for _name, kind, _flags, _addr, offset, size, link, _info, _align, entsize in sections:
        if kind != 11:  # SHT_DYNSYM
            continue
        strtab = sections[link][4]
        for pos in range(offset, offset + size, entsize):
            st_name, _st_info, _other, shndx, value, _size = struct.unpack_from("<IBBHQQ", elf, pos)
            end = elf.index(b"\0", strtab + st_name)
            if shndx and elf[strtab + st_name:end] == name:
                sec_addr, sec_offset = sections[shndx][3], sections[shndx][4]
                return value - sec_addr + sec_offset
    raise WrapperError(f"wrapper binary: symbol {name.decode()} not found")


def patch_binary(data: bytes) -> bytes:
    """pythonfmu 0.7.0's linux64 wrapper with ``finalizePythonInterpreter`` reduced to ``ret`` (module docstring).

    Parameters
    ----------
    data : bytes
        The wrapper binary as pythonfmu 0.7.0 ships it (or as this function returned it).

    Returns
    -------
    bytes
        The patched binary (unchanged when ``data`` is already patched).

    Raises
    ------
    WrapperError
        If ``data`` is neither the pinned binary nor its patched form.
    """
    digest = hashlib.sha256(data).hexdigest()
    if digest == _PATCHED_SHA256:
        return data
    if digest != _ORIGINAL_SHA256:
        raise WrapperError(f"wrapper binary (sha256 {digest[:16]}...) is not pythonfmu {PINNED_VERSION}'s "
                           f"libpythonfmu-export.so; reinstall pythonfmu=={PINNED_VERSION}")
    at = _symbol_offset(data, _SYMBOL)
    if data[at:at + 4] != _ENDBR64 or data[at + 4] != _PUSH_RBP:
        raise WrapperError(f"wrapper binary: {_SYMBOL.decode()} does not start as expected")
    patched = bytearray(data)
    patched[at + 4] = _RET
    result = bytes(patched)
    if hashlib.sha256(result).hexdigest() != _PATCHED_SHA256:
        raise WrapperError("wrapper binary: the patched binary does not have the expected checksum")
    return result


def patch_fmu(fmu: Path) -> None:
    """Rewrite an FMU archive in place with its linux64 wrapper binary patched (:func:`patch_binary`).

    Raises
    ------
    WrapperError
        If the FMU has no linux64 binary or that binary is not pythonfmu 0.7.0's.
    """
    with zipfile.ZipFile(fmu) as z:
        entries = [(info, z.read(info)) for info in z.infolist()]
    targets = [info.filename for info, _ in entries
               if info.filename.startswith("binaries/linux64/") and info.filename.endswith(".so")]
    if len(targets) != 1:
        raise WrapperError(f"{fmu.name}: expected one linux64 binary, found {len(targets)}")
    tmp = fmu.with_name(fmu.name + ".patching")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as out:
        for info, payload in entries:
            out.writestr(info, patch_binary(payload) if info.filename == targets[0] else payload)
    tmp.replace(fmu)
