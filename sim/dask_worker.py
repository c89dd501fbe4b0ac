"""The preload of the Dask workers that ``--scheduler local`` starts (``distributed``'s ``dask_setup`` hook).

Ctrl-C in a terminal reaches the whole process group, the local cluster's worker processes too; each
would print a traceback of its own. They ignore SIGINT instead: the command answers it, and ending the
cluster ends them (as :class:`sim.workers.WorkerPool`'s workers do).
"""

from __future__ import annotations

import signal


def dask_setup(worker) -> None:
    """Called by each worker as it starts, in its process's main thread."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
