"""What plugs the hardware-in-the-loop room (:mod:`ipcosim.fmus.hil`: card API, wire protocol, adapter
FMU, in-process card, virtual rig and its server) into the master: the observer of a run's cards
(:mod:`.observer`, a master :class:`~ipcosim.harness.master.observers.Observer`) and the
``--swap plant=hil`` alias (:mod:`.swap`, registered with the scenario binding when this package is
imported). A plain simulation loads none of it.
"""
from __future__ import annotations

from ipcosim.harness.hil import swap as _swap  # noqa: F401 -- registers the ``hil`` swap alias
