"""The thesis's own evidence, over the generic study engine (:mod:`ipcosim.harness.studies`).

The claims judged on the thesis's terms (:mod:`.claims`), the fitted passive-cart friction
(:mod:`.friction`), the pure-loop table of docs/controllers.md (:mod:`.controllers_table`),
docs/results.md (:mod:`.results_page`) and the cross-checks against other importers of the
same scenarios (:mod:`.crosscheck`: libcosim, FMPy; :mod:`.fmi_crosscheck`: the FMI
cross-check layout). Not installed: run from a clone (``python -m evidence.<module>``); it imports the
package, never the other way round.
"""
