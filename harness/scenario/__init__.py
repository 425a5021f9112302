"""Scenarios: SSP files read and schema-checked into a frozen ``Scenario`` (``ssp``, its errors in
``errors``), safe archive extraction, the binding to the FMUs (``binding.bind``: parameters, swaps,
``--set`` values in one place) over one module per idea (``model_description``, ``swaps``, ``units``,
``values``, ``transformations``, ``checks``, ``rebuild``), the default experiment, the FMU flavours and
the ``.ssp`` packer.

May import: ``harness.master`` (the system types it builds), ``ipcosim.errors``, ``harness.paths``;
``harness.native`` (the native flavour's values, its build folders) and ``fmus.pybuild`` (whether a
built FMU is older than its sources).
"""
