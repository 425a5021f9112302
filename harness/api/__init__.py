"""The public run API behind ``ipcosim.run`` and the command line's ``run``: the run options (``options``,
their value grammar ``grammar``), the engine that prepares and runs a scenario (``engine``), the public
functions (``public``), and what presents a scenario or a run (``describe``, ``plot``) or packs its loop
as one FMU (``export``). Re-exported lazily at the top of the package (``ipcosim/__init__.py``)."""
