"""The IP02 plants: physics, parameters, integrator and linearization (pure Python), the plant
FMUs and the HIL adapter FMU (thin glue over ``fmi``), the HIL card API (``hil``), the FMU
build and the native C generator (``native``).

May import: ``ipcosim.errors`` and the standard library (numpy, scipy only in analysis
code, never on an FMU's default path). Nothing of ``controllers`` or ``harness``, except
``native``, a build tool that reads the controllers' definitions.
"""
