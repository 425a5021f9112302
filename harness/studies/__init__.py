"""The generic study engine: the sweep (``sweep``; its runs ``cases``, ``executors``, ``store``,
``progress``), run specifications, robustness, tuning, analysis, identification (``identify``:
the plant's parameters from a run's log) and the controller comparison report. The ``--vary``
grammar is :mod:`ipcosim.harness.api.grammar`; the thesis's own evidence, over this engine, is not
installed (it lives in the repository: docs/architecture.md). May import every room below the command line."""
