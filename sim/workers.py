"""A local process pool that Ctrl-C stops at once and never leaves waiting: :class:`WorkerPool`.

Ctrl-C in a terminal sends SIGINT to the whole process group, workers included.  Three things make
the commands that run on a pool (``study``, a ``flatten`` batch) end within a moment, with one line
and nothing else:

- the workers ignore SIGINT: the parent answers it for all of them, and no worker prints a
  traceback of its own;
- a task is submitted with SIGINT held back (:func:`sim.outputs.deferred_interrupts`).  The first
  submit forks the workers and starts the executor's thread; a ``KeyboardInterrupt`` raised in the
  middle of that leaves workers the executor has not recorded, blocked on its queue, and the
  program's exit waits for them for ever;
- leaving the ``with`` block by an exception ends the workers (their runs are lost) instead of
  waiting for the runs in flight.
"""

from __future__ import annotations

import signal
from concurrent.futures import Future, ProcessPoolExecutor
from typing import Any, Callable

from .outputs import deferred_interrupts

__all__ = ["WorkerPool"]


def _start_worker(initializer: Callable[..., None] | None, initargs: tuple) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if initializer is not None:
        initializer(*initargs)


class WorkerPool(ProcessPoolExecutor):
    """A :class:`~concurrent.futures.ProcessPoolExecutor` of ``max_workers`` processes whose workers
    ignore SIGINT, whose start cannot be cut in half by it, and which :meth:`stop` ends at once."""

    def __init__(self, max_workers: int, initializer: Callable[..., None] | None = None, initargs: tuple = ()):
        super().__init__(max_workers, initializer=_start_worker, initargs=(initializer, initargs))

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future:
        with deferred_interrupts():
            return super().submit(fn, *args, **kwargs)

    def stop(self) -> None:
        """Cancel the queued tasks, end the workers (the runs in flight are lost) and wait for the
        executor's thread."""
        # ProcessPoolExecutor has no public way to end its workers before Python 3.14 (terminate_workers)
        processes = list((self._processes or {}).values())
        thread = self._executor_manager_thread
        self.shutdown(wait=False, cancel_futures=True)
        for process in processes:
            process.terminate()
        for process in processes:
            process.join()
        if thread is not None:
            thread.join()

    def __exit__(self, exc_type, exc_value, traceback) -> bool:
        if exc_type is None:
            self.shutdown(wait=True)
        else:
            self.stop()
        return False
