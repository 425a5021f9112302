"""Studies at scale: parameter variation grammar, run specifications, robustness, tuning
and the controller comparison report. The sweep engine itself is ``ipcosim.harness.studies.sweep``."""
