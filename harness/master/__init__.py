"""The co-simulation master: slaves (one FMU instance each), algorithms (Gauss-Seidel,
Jacobi), the execution that owns them and runs the FMI lifecycle, its value layout (where every
connector's value lives) and recorder (the rows and the result), the stepping loop's plan and
its two renderings, observers, manipulators, real-time pacing and results. ``system``
describes what it runs.

May import: ``ipcosim.errors``, ``ipcosim.toolchain``, ``harness.paths`` and ``harness.extras``.
It knows nothing of pendulums, laws, cards, scenario files, studies or the command line: task
metrics come in as plug-ins.
"""
