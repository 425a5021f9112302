"""pythonfmu's C++ wrapper binary: the pinned version, the two edits every FMU build applies to it,
and the module file every FMU build gives it.

Every ipcosim FMU runs inside pythonfmu 0.7.0's FMI wrapper (``binaries/linux64/<Model>.so``,
a copy of ``pythonfmu/resources/binaries/linux64/libpythonfmu-export.so``). Each FMU binary
keeps its own interpreter guard (``PyState``) in a static ``std::shared_ptr``; the guard's
thread calls ``Py_Initialize`` when it finds Python uninitialized (a host that is not Python)
and ``Py_Finalize`` when the guard is destroyed. Two behaviours of that binary crash hosts at
exit; :func:`patch_binary` answers each with the smallest edit of the machine code:

1. **Double free at every exit, in every host.** The library also resets the static pointer
   from an ELF destructor (``__attribute__((destructor)) onLibraryUnload ->
   finalizePythonInterpreter: pyState = nullptr``). At process exit glibc runs the C++ static
   destructors (``__cxa_atexit``) *before* the ELF destructors (``_dl_fini``), so
   ``finalizePythonInterpreter`` releases a ``shared_ptr`` already destroyed: it decrements the
   use count inside the freed control block and, when the freed memory still reads 1, destroys
   the ``PyState`` and frees the block again. The heap is corrupted and the process aborts at
   some later free (``corrupted double-linked list`` in libgfortran's exit handler, in fmpy
   and pytest processes). Valgrind shows it on every exit::

       Invalid read of size 4
          at finalizePythonInterpreter (in .../binaries/linux64/Setpoint.so)
          by _dl_call_fini / _dl_fini / __run_exit_handlers / exit
        Address ... is 8 bytes inside a block of size 128 free'd
          at operator delete / __run_exit_handlers / exit
        Block was alloc'd at operator new / pythonfmu::createInstance / fmi2Instantiate

   Edit: ``finalizePythonInterpreter`` returns at once (after ``endbr64``, ``push %rbp`` ->
   ``ret``); the static destructor alone releases the guard, once, on every path. (When a
   host's ``dlclose`` does unload a binary, glibc runs the ELF destructors before the
   library's C++ static destructors, so that path was already in the right order; the first
   of these binaries loaded in a process is never unloaded, as the later ones bind its
   GNU-unique symbols.)

2. **Py_Finalize from an exit handler, in hosts that are not Python.** The guard of the
   binary that initialized Python is destroyed by its ``__cxa_atexit`` handler, which makes
   its thread call ``Py_Finalize`` while the process is exiting: the exit handlers of every
   library loaded after it (NumPy's, SciPy's C++ extension modules, other FMUs) have already
   run, and the finalizer's garbage collection frees objects whose native state is gone
   (SIGSEGV in ``Py_FinalizeEx -> finalize_modules -> gc -> _uarray Function::clear ->
   dict_dealloc -> _PyObject_Free``, in 5 of 8 exits of a C host).
   Edit: in ``PyState::Worker`` the branch taken only by the thread that initialized Python,
   ``call PyEval_RestoreThread; call Py_Finalize`` become no-ops: an interpreter an FMU
   started stays alive, with the GIL released, until the process ends (the operating system
   reclaims it; a host's own exit handlers may still call ``fmi2FreeInstance``). Python-level
   ``atexit`` hooks of the FMU code do not run; the FMU runtime registers none.

The edits are made on the exact binary of pythonfmu 0.7.0 only (SHA-256 checked before and
after, and the original bytes at each site); any other pythonfmu fails the build with one line
naming the pinned version. The win64 binary is left as pythonfmu ships it.

3. **The FMU module evaluated again at every instantiation.** At each ``fmi2Instantiate`` the
   wrapper (``findClass``) imports the module named in ``resources/slavemodule.txt``, then reads
   that module's file, compiles it and evaluates it once more, with the module's ``__dict__`` as
   globals and a fresh dict as locals; it looks among the classes in those locals for the deepest
   ``Fmi2Slave`` subclass and takes the module's attribute of that name. Every class the
   evaluation makes stays alive (the wrapper never releases the list of its MRO, nor the repr
   strings it reads the names from), and it releases one reference to the module's ``__dict__``
   that it never took: 6.9-8.9 KB left behind per instantiation and free, in fmpy, for a plant
   and a controller. Answer (:func:`module_stub`, :func:`stub_fmu`): the module file the wrapper
   evaluates is a stub; the FMU script runs once, at the import, in the module's namespace (from
   ``resources/<private package>/<script>``), and the stub stores its FMU class as the module's
   attribute ``""``. The evaluations then define nothing, the wrapper's search finds no class and
   takes the attribute ``""``, which is the FMU class, and each evaluation takes the reference the
   wrapper then releases. The FMU runs the same code, with the same class and module names.
   Compiling the stub at every instantiation also interns its identifier-like constants: it names the
   script in one constant that is not an identifier (:func:`module_stub`), and every other name it holds
   stays alive in the process, so an instantiation takes no new slot of the interpreter's table of
   interned strings (the FMU glue holds the private package's name, ``ipcosim.fmus.fmi_fixes._PACKAGE``).
"""
from __future__ import annotations

import hashlib
import struct
import zipfile
from dataclasses import dataclass
from pathlib import Path

import pythonfmu

from ipcosim.errors import IpcosimError

__all__ = ["PINNED_VERSION", "PATCH_ID", "WrapperError", "check_pythonfmu", "module_stub", "patch_binary",
           "patch_fmu", "stub_fmu"]

#: The pythonfmu release whose wrapper binary the patch and the glue in ``ipcosim.fmus.fmi`` answer.
PINNED_VERSION = "0.7.0"
#: Names the patch in the build stamp, so FMUs built before (or after) a change of it are rebuilt.
PATCH_ID = "pythonfmu-0.7.0-exit-2-stub-2"
_ORIGINAL_SHA256 = "4be156a552c16f30eb4395805c59855d8d4086056d0f165442565f6c5fbac0c9"
_PATCHED_SHA256 = "1087129bcbeb8bef99fbdf6df9f7a090175343c2da86c0bcffcbfe97db797651"
_NOP5 = bytes.fromhex("0f1f440000")


@dataclass(frozen=True)
class _Site:
    """One edit: at ``offset`` bytes into the exported function ``symbol``, ``old`` becomes ``new``."""

    symbol: bytes
    offset: int
    old: bytes
    new: bytes


_SITES = (
    # 1. finalizePythonInterpreter: after endbr64, ``push %rbp`` -> ``ret``.
    _Site(b"finalizePythonInterpreter", 4, bytes.fromhex("55"), bytes.fromhex("c3")),
    # 2. PyState::Worker, the branch taken only where the wrapper initialized Python itself:
    #    ``call PyEval_RestoreThread; call Py_Finalize`` -> two 5-byte no-ops.
    _Site(b"_ZN9pythonfmu7PyState6WorkerEv", 0xAC, bytes.fromhex("e83f25feffe81a27feff"),
          _NOP5 + _NOP5),
)


class WrapperError(IpcosimError, RuntimeError):
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
    """pythonfmu 0.7.0's linux64 wrapper with the two exit-time edits of the module docstring.

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
    patched = bytearray(data)
    for site in _SITES:
        at = _symbol_offset(data, site.symbol) + site.offset
        if data[at:at + len(site.old)] != site.old:
            raise WrapperError(f"wrapper binary: unexpected code at {site.symbol.decode()}+{site.offset:#x}")
        patched[at:at + len(site.old)] = site.new
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


def module_stub(doc: str | None, private: str, script: str, class_name: str) -> str:
    """The module file pythonfmu's wrapper evaluates at every instantiation (module docstring, 3):
    at the import it runs ``resources/<private>/<script>`` in the module's namespace and stores the
    class ``class_name`` as the attribute ``""``; every later evaluation defines nothing and takes
    one reference to the module's namespace (``Py_IncRef`` through ctypes, so an FMU whose runtime lacks the
    project's FMU base, such as a user's, is stubbed the same way).
    ``doc`` is the script's docstring, kept as the stub's. The script's path is one constant that is not an
    identifier: the wrapper compiles this file at every instantiation, and compiling interns every identifier-like
    string constant (a private package name alone would be interned, and freed, once per instantiation)."""
    return (f'{(repr(doc) if doc else "")}\n'
            "# pythonfmu 0.7.0's wrapper evaluates this file again at every instantiation and keeps every class\n"
            f"# that defines: the FMU's code is {private}/{script}, run once, at the import, in this module.\n"
            'if "" not in globals():\n'
            "    import os as _os\n"
            f"    _path = _os.path.join(_os.path.dirname(__file__), {private + '/' + script!r})\n"
            '    with open(_path, encoding="utf-8") as _file:\n'
            '        exec(compile(_file.read(), _path, "exec"), globals())\n'
            f'    globals()[""] = {class_name}\n'
            "    del _os, _path, _file\n"
            "else:  # the wrapper's evaluation, which then releases a reference to this namespace it never took\n"
            "    import ctypes as _ctypes\n"
            "    _ctypes.pythonapi.Py_IncRef(_ctypes.py_object(globals()))\n"
            "    del _ctypes\n")


def stub_fmu(fmu: Path, private: str, class_name: str) -> None:
    """Rewrite an FMU archive in place so that the module its ``slavemodule.txt`` names is
    :func:`module_stub` over the script, moved to ``resources/<private>/``.

    Raises
    ------
    WrapperError
        If the FMU lacks ``resources/slavemodule.txt`` or the module file it names.
    """
    with zipfile.ZipFile(fmu) as z:
        entries = [(info, z.read(info)) for info in z.infolist()]
    files = {info.filename: payload for info, payload in entries}
    module = files.get("resources/slavemodule.txt", b"").decode().strip()
    name = f"resources/{module}.py"
    if not module or name not in files:
        raise WrapperError(f"{fmu.name}: no FMU module named in resources/slavemodule.txt")
    import ast

    doc = ast.get_docstring(ast.parse(files[name]), clean=False)
    stub = module_stub(doc, private, f"{module}.py", class_name).encode()
    tmp = fmu.with_name(fmu.name + ".stubbing")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as out:
        for info, payload in entries:
            if info.filename == name:
                out.writestr(f"resources/{private}/{module}.py", payload)
                out.writestr(info, stub)
            else:
                out.writestr(info, payload)
    tmp.replace(fmu)
