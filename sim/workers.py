"""A local process pool that Ctrl-C stops at once and never leaves waiting: :class:`WorkerPool`.

Ctrl-C in a terminal sends SIGINT to the whole process group, workers included.  Four things make
the commands that run on a pool (``study``, a ``flatten`` batch) end within a moment, with one line
and nothing else:

- the workers ignore SIGINT: the parent answers it for all of them, and no worker prints a
  traceback of its own; and SIGTERM, which :meth:`WorkerPool.stop` ends them with (and SIGHUP, which
  a closed terminal sends them), has its default action in a forked child, not the command's handler
  (which would raise in the worker, or never run in one stuck on a lock another thread held at the
  fork); a signal the program ignores (``nohup``'s SIGHUP) its workers ignore too;
- a task is submitted with SIGINT, SIGTERM and SIGHUP held back (:func:`sim.outputs.deferred_interrupts`).
  The first submit forks the workers and starts the executor's thread; a ``KeyboardInterrupt`` raised in the
  middle of that leaves workers the executor has not recorded, blocked on its queue, and the
  program's exit waits for them for ever;
- leaving the ``with`` block by an exception ends the workers (their runs are lost) instead of
  waiting for the runs in flight;
- the main thread waits on the workers in slices (:func:`wait_for_one`): the kernel may hand the signal
  to a pool's thread, and CPython runs the handler in the main thread only.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import sys
import threading
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from typing import Any, Callable, Iterable

from .outputs import deferred_interrupts

__all__ = ["WorkerPool", "wait_for_one", "result_of", "usable_cores", "local_workers", "check_scheduler_address",
           "MAX_WORKERS_PER_CORE"]

#: Local worker processes per usable core at most (``flatten --jobs``, ``study --jobs``): each is a
#: Python process with numpy and the model; more would only share the cores and fill the memory.
MAX_WORKERS_PER_CORE = 4


def usable_cores() -> int:
    """The cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def local_workers(value: int | None, option: str, scheduler: str | None = None) -> int:
    """The local worker processes ``option`` asks for (``None``: one per usable core); a
    :class:`~golden_model.params.ParameterError` below 1 or above :data:`MAX_WORKERS_PER_CORE` per core, or
    given beside a Dask ``scheduler`` address (whose cluster has its own workers); a malformed address
    (:func:`check_scheduler_address`)."""
    from golden_model.params import ParameterError

    if scheduler not in (None, "local"):
        check_scheduler_address(scheduler)  # a malformed address refused now, not after Dask's timeout
    if value is not None and scheduler not in (None, "local"):
        raise ParameterError(f"{option} sets the local worker processes; the Dask scheduler at '{scheduler}' has "
                             f"its own workers: drop {option}")
    cores = usable_cores()
    if value is None:
        return cores
    if value < 1:
        raise ParameterError(f"{option} must be >= 1, got {value}")
    if value > MAX_WORKERS_PER_CORE * cores:
        raise ParameterError(f"{option} {value}: at most {MAX_WORKERS_PER_CORE * cores} local worker processes "
                             f"({MAX_WORKERS_PER_CORE} per core, {cores} here); more would only share the cores and "
                             "fill the memory")
    return value


def check_scheduler_address(scheduler: str) -> None:
    """Refuse a ``--scheduler`` address that Dask could never connect to: an unknown protocol, no host, or a
    port that is no number in 1-65535 (Dask would try it until its timeout)."""
    from distributed.comm import parse_address
    from distributed.comm.addressing import parse_host_port
    from distributed.comm.registry import backends, get_backend

    from golden_model.params import ParameterError

    expected = "expected 'local' or PROTOCOL://HOST:PORT, such as tcp://host:8786"
    try:
        protocol, location = parse_address(scheduler)
        # tcp and tls need a port (Dask's Client refuses an address without one); a websocket's is its URL's
        host, port = (parse_host_port(location, 0) if protocol in ("tcp", "tls") else
                      parse_host_port(location, 8786) if protocol in ("ws", "wss") else (location, 1))
    except (ValueError, TypeError):
        raise ParameterError(f"--scheduler '{scheduler}': not a Dask address ({expected})") from None
    if port == 0 and not location.endswith(":0"):
        raise ParameterError(f"--scheduler '{scheduler}': no port ({expected})")
    try:
        get_backend(protocol)  # (loads a plug-in's protocol from its entry point)
    except (ValueError, ImportError):  # unknown, or a plug-in that cannot be loaded
        raise ParameterError(f"--scheduler '{scheduler}': Dask has no protocol '{protocol}' "
                             f"({', '.join(sorted(backends))})") from None
    if not host or not 1 <= port <= 65535:
        problem = "no host" if not host else f"port {port} is not in 1-65535"
        raise ParameterError(f"--scheduler '{scheduler}': {problem} ({expected})")


#: The signals a worker takes with their default action (it ends at once): SIGTERM, which
#: :meth:`WorkerPool.stop` sends, and SIGHUP, which a closed terminal sends the whole group; one the
#: program ignores (``nohup``'s SIGHUP) its workers ignore too.
_DEFAULT_IN_WORKERS = (signal.SIGTERM, signal.SIGHUP)
#: The handlers a worker's fork set aside in the main thread, to be put back in the parent after it.
_HANDLERS_BEFORE_FORK: list[dict] = []
#: Set while a :class:`WorkerPool` may fork its workers (in its ``submit``): only those forks are touched.
_FORKING_WORKERS = threading.Event()


def _default_actions_for_the_fork() -> None:
    if _FORKING_WORKERS.is_set() and threading.current_thread() is threading.main_thread():  # (signal.signal)
        # held back while the handlers are swapped: one arriving now is answered by the parent's handler after
        # the fork (the child starts with none pending)
        signal.pthread_sigmask(signal.SIG_BLOCK, _DEFAULT_IN_WORKERS)
        _HANDLERS_BEFORE_FORK.append({n: signal.signal(n, signal.SIG_DFL) for n in _DEFAULT_IN_WORKERS
                                      if signal.getsignal(n) not in (signal.SIG_IGN, None)})


def _handlers_back_in_the_parent() -> None:
    if _HANDLERS_BEFORE_FORK and threading.current_thread() is threading.main_thread():
        for signum, handler in _HANDLERS_BEFORE_FORK.pop().items():
            signal.signal(signum, handler)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, _DEFAULT_IN_WORKERS)


def _default_actions_in_the_child() -> None:
    if _HANDLERS_BEFORE_FORK:  # a worker's fork: its default actions (or ignored signals) are already its own
        _HANDLERS_BEFORE_FORK.clear()
        signal.pthread_sigmask(signal.SIG_UNBLOCK, _DEFAULT_IN_WORKERS)


# SIGTERM's and SIGHUP's default actions are set around a worker's fork, so the worker has them from its
# first instruction; the forks of a program that uses the API are left alone (its children keep its handlers).
os.register_at_fork(before=_default_actions_for_the_fork, after_in_parent=_handlers_back_in_the_parent,
                    after_in_child=_default_actions_in_the_child)


#: Seconds the main thread waits on its workers at a time (:func:`wait_for_one`).
WAIT_SLICE_S = 0.2


#: glibc's ``mallopt`` parameters and the values its own dynamic thresholds grow to on a 64-bit machine
#: (``DEFAULT_MMAP_THRESHOLD_MAX``, and twice that to trim).
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_MMAP_THRESHOLD = 32 << 20
_TRIM_THRESHOLD = 2 * _MMAP_THRESHOLD


#: The trim threshold Dask's nanny gives its workers (``distributed.nanny.pre-spawn-environ``).
DASK_MALLOC_TRIM_THRESHOLD = "65536"


def undo_dask_malloc_trim() -> None:
    """In a Dask worker started with Dask's ``MALLOC_TRIM_THRESHOLD_=65536``, glibc's thresholds set where its
    own dynamic ones end on a 64-bit machine (an mmap threshold of 32 MiB, a trim threshold of 64 MiB): Dask's
    value also stops glibc raising its mmap threshold, so each of a large mesh's arrays is mapped afresh and handed
    back at once, page fault by page fault (measured in docs/patterns.md, "Large meshes on Dask"). Nothing outside a
    Dask worker (the command, its process pool, an API caller's executor), where the variable has another value
    (the user's), or where glibc is not the C library; the thresholds stay for the worker's later tasks."""
    if os.environ.get("MALLOC_TRIM_THRESHOLD_") != DASK_MALLOC_TRIM_THRESHOLD or "distributed" not in sys.modules:
        return
    from distributed import get_worker

    try:
        get_worker()
    except ValueError:  # (not in a worker's task)
        return
    import ctypes
    import ctypes.util

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        libc.mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD)
        libc.mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD)
    except (OSError, AttributeError):  # no glibc (musl, macOS): its allocator does not read the variable
        pass


def wait_for_one(futures: Iterable[Future]) -> set[Future]:
    """The futures of ``futures`` that are done, once at least one is, waited for in slices of
    :data:`WAIT_SLICE_S`. The kernel may hand a Ctrl-C (SIGINT to the process) to any of its threads, a pool's
    manager or feeder thread too; CPython then only notes it, and runs the Python handler when the main thread
    next runs bytecode. A wait without a timeout would hold the main thread until a run ends (minutes): a
    wait in slices answers the signal within one, at the end of the slice. Not inside it: ``wait`` takes every
    future's lock in turn, and a ``KeyboardInterrupt`` raised between two would leave a lock held, and the
    thread that completes that future (a pool's, Dask's client loop) blocked on it for ever."""
    futures = list(futures)
    if not futures:
        return set()
    while True:
        with deferred_interrupts():
            done, _ = wait(futures, timeout=WAIT_SLICE_S, return_when=FIRST_COMPLETED)
        if done:
            return done


def result_of(future: Future) -> Any:
    """``future.result()``, waited for as :func:`wait_for_one` waits: a Ctrl-C is answered within a slice."""
    wait_for_one([future])
    return future.result()


def _start_worker(parent: int, initializer: Callable[..., None] | None, initargs: tuple) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _die_with(parent)
    if initializer is not None:
        initializer(*initargs)


def _die_with(parent: int) -> None:
    """End this worker when the process ``parent`` that forked it dies, even by SIGKILL, which gives it no
    chance to stop its workers, which would wait on its pipe (Linux's ``PR_SET_PDEATHSIG``, best effort:
    nothing is done elsewhere, where the call is missing, or for a worker a fork server or spawn started,
    whose parent is not ``parent``)."""
    if sys.platform != "linux" or os.getppid() != parent:
        return
    try:
        import ctypes

        pr_set_pdeathsig = 1
        ctypes.CDLL(None).prctl(pr_set_pdeathsig, int(signal.SIGKILL), 0, 0, 0)
    except (OSError, AttributeError):
        return
    if os.getppid() != parent:  # it died between the two checks: nobody is left to send the signal
        os._exit(1)


def _start_method() -> str | None:
    """How workers start: forked on Linux while the process has one thread (they share the parent's imports,
    and a caller's script does not run again in them, as under ``spawn`` or ``forkserver``, which a program
    may have chosen, and which re-import its main module); elsewhere, or beside other threads (where forking
    is unsafe), the system's default."""
    return "fork" if sys.platform == "linux" and threading.active_count() == 1 else None


class WorkerPool(ProcessPoolExecutor):
    """A :class:`~concurrent.futures.ProcessPoolExecutor` of ``max_workers`` processes whose workers
    ignore SIGINT, whose start cannot be cut in half by it, which :meth:`stop` ends at once, and which end
    when their parent dies (:func:`_die_with`); forked
    where that is safe, whatever start method the program chose (:func:`_start_method`)."""

    def __init__(self, max_workers: int, initializer: Callable[..., None] | None = None, initargs: tuple = ()):
        super().__init__(max_workers, initializer=_start_worker, initargs=(os.getpid(), initializer, initargs),
                         mp_context=multiprocessing.get_context(_start_method()))

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future:
        with deferred_interrupts():  # (the workers are forked here: ProcessPoolExecutor starts them in submit)
            _FORKING_WORKERS.set()
            try:
                return super().submit(fn, *args, **kwargs)
            finally:
                _FORKING_WORKERS.clear()

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
