"""Hardware-in-the-loop above the master: the virtual rig's network server and service
(``ipcosim rig serve``, :mod:`.server`, :mod:`.service`), the observer of a run's cards
(:mod:`.observer`, a master :class:`~ipcosim.harness.master.observers.Observer`) and the
``--swap plant=hil`` alias (:mod:`.swap`, registered with the scenario binding when this
package is imported).

What runs inside the HIL adapter FMU (the card API, its clients, the wire format, the virtual
rig an in-process card drives) stays in :mod:`ipcosim.fmus.hil`: the FMU carries it.
"""
from __future__ import annotations

from ipcosim.harness.hil import swap as _swap  # noqa: F401 -- registers the ``hil`` swap alias
