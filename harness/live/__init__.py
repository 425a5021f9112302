"""The live view: a run in the browser as it happens (``ipcosim run --live``), and a finished run or a
sweep's table (``ipcosim view``). See docs/live.md.

:mod:`~ipcosim.harness.live.feed` is the observer the run hands its samples to (the master's
interface, nothing per step beyond an append into shared memory); :mod:`~ipcosim.harness.live.scene`
what the page draws, after the plant kind; :mod:`~ipcosim.harness.live.server` the page and its JSON;
:mod:`~ipcosim.harness.live.session` a live run's feed and the process of its own that serves its
page; :mod:`~ipcosim.harness.live.view` a finished run's and a sweep's pages.
"""
