"""The controllers: designs (python-control and scipy, imported on demand), the discrete
control laws (plain floats), the identification excitation (``excitation``), parameter sets and the
controller FMUs (thin glue).

May import: ``ipcosim.fmus`` (the plant's physics and FMI glue), ``ipcosim.errors``.
Nothing of ``harness``.
"""
