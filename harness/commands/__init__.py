"""Sub-commands of the ``ipcosim`` command line (see ``harness.cli``)."""
