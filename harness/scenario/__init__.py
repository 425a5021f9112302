"""Scenarios: SSP files read and schema-checked into a frozen ``Scenario`` (``ssp``), safe
archive extraction, binding to the FMUs (``binding.bind``: parameters, swaps, ``--set`` values in one
place), the FMU flavours, the scenario generator and the ``.ssp`` packer.

May import: ``harness.master`` (the system types it builds), ``ipcosim.errors``,
``harness.extras``; ``controllers`` in the generator only.
"""
