"""The controllers: designs (python-control and scipy, imported on demand), the discrete
control laws (plain floats), one module per law family in ``laws`` (with the identification
excitation) holding its parameter sets and linear model, the registry of the laws (``catalog``) and
the controller FMUs (thin glue).

May import: ``ipcosim.fmus`` (the plant's physics and FMI glue), ``ipcosim.errors``.
Nothing of ``harness``.
"""
