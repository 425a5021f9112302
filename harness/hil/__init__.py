"""The rig side of hardware-in-the-loop: the rig server (:mod:`.server`, ``ipcosim rig
serve``: a virtual IP02 served over TCP) and the ``--swap plant=hil`` alias (:mod:`.swap`).

The card API the adapter FMU drives (a real Q4, the TCP client, the in-process backend and
the virtual rig behind it) is :mod:`ipcosim.fmus.hil`, below the FMU glue.
"""
