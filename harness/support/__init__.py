"""What every harness room below the master may use: where things are found and built (``paths``), the
check for a missing optional dependency (``extras``) and the numeric libraries kept to one thread
(``threads``)."""
