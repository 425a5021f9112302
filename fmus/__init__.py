"""The IP02 plants: physics, parameters, integrator and linearization (pure Python), the task
metrics (``metrics``), the plant FMUs (thin glue over ``fmi``), the Python FMU build and its
cache (``pybuild``), and all of hardware-in-the-loop (``hil``: card API, virtual rig, adapter
FMU glue, rig server, swap alias, card observer).

May import: ``ipcosim.errors`` and the standard library (numpy, scipy only in analysis
code, never on an FMU's default path). Nothing of ``controllers`` or ``harness``.
"""
