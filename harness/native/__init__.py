"""The native flavour: C source-code FMUs generated from the same Python models, and the loop
container of ``ipcosim export`` (a build tool; see docs/native.md).

May import: ``ipcosim.fmus`` and ``ipcosim.controllers`` (it traces the plants and the laws),
``ipcosim.errors``, ``ipcosim.toolchain``. Nothing of the master, the scenarios or above.
"""
