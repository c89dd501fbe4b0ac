"""sim.workers.WorkerPool: workers that ignore SIGINT, and an exit by exception that ends them.

(The pool's start under SIGINT, the window where a Ctrl-C used to leave the program waiting for ever,
is checked on the real program: tests/sim/test_fuzz_cli.py.)"""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys
import threading
import time
from concurrent.futures import Future, _base
from concurrent.futures.process import BrokenProcessPool

import pytest

from sim.workers import WorkerPool, wait_for_one
from support import REPO


def _interrupt_myself_then_answer() -> int:
    os.kill(os.getpid(), signal.SIGINT)
    time.sleep(0.2)  # the signal is handled (or ignored) before the answer
    return 7


def _ignores_sigint() -> bool:
    return signal.getsignal(signal.SIGINT) is signal.SIG_IGN


def _record(path: str) -> None:
    global _RECORDED
    _RECORDED = path


_RECORDED = ""


def _recorded() -> str:
    return _RECORDED


def test_a_worker_ignores_sigint_and_finishes_its_task():
    """Ignored, not only swallowed by the handler a worker forked under held-back SIGINT inherits."""
    with WorkerPool(1) as pool:
        assert pool.submit(_ignores_sigint).result(timeout=60)
        assert pool.submit(_interrupt_myself_then_answer).result(timeout=60) == 7


def test_the_callers_initializer_still_runs_in_each_worker():
    with WorkerPool(1, initializer=_record, initargs=("given",)) as pool:
        assert pool.submit(_recorded).result(timeout=60) == "given"


def test_leaving_the_pool_by_an_exception_ends_the_runs_in_flight():
    """Not waited for: the running task is lost (the pool is broken) and every worker has ended."""
    with pytest.raises(RuntimeError, match="stop"):
        with WorkerPool(2) as pool:
            future = pool.submit(time.sleep, 60)
            processes = list(pool._processes.values())
            while not future.running():
                time.sleep(0.01)
            raise RuntimeError("stop")
    assert future.done() and isinstance(future.exception(timeout=0), BrokenProcessPool)
    assert not any(process.is_alive() for process in processes)


def test_leaving_the_pool_normally_waits_for_the_tasks():
    with WorkerPool(2) as pool:
        futures = [pool.submit(pow, 2, n) for n in range(8)]
    assert [f.result(timeout=0) for f in futures] == [2 ** n for n in range(8)]


def _slim_that_takes_a_minute(mesh):
    time.sleep(60)
    with open(os.environ["SLIM_FINISHED"], "w") as done:  # (only if the worker was awaited, not stopped)
        done.write("finished")


def test_slim_beside_arap_gives_slims_layout_and_leaves_no_process(monkeypatch, tmp_path):
    import multiprocessing

    import numpy as np

    from sim.layouts import slim_layout
    from sim.mesh_io import load_mesh
    from golden_model.params import FlattenParams
    from sim import run_options
    from support import SCANS

    mesh = load_mesh(SCANS / "bunny_ear.obj")
    monkeypatch.setattr(run_options, "SLIM_BESIDE_ARAP_VERTICES", 1)
    with run_options.slim_beside_arap(mesh, enabled=True) as slim:
        assert slim is not None and multiprocessing.active_children()
        np.testing.assert_array_equal(slim(), slim_layout(mesh))  # the same function, the same bytes
    assert not multiprocessing.active_children()
    monkeypatch.setattr(run_options, "slim_layout", _slim_that_takes_a_minute)
    monkeypatch.setenv("SLIM_FINISHED", str(tmp_path / "finished"))
    with run_options.slim_beside_arap(mesh, enabled=True) as slim:  # not asked for: ARAP did not fold
        pass
    assert not multiprocessing.active_children() and not (tmp_path / "finished").exists()  # stopped, not awaited
    monkeypatch.undo()
    with run_options.slim_beside_arap(mesh, enabled=False) as slim:
        assert slim is None
    guarded = FlattenParams(dynamics="momentum")
    alone, beside = (run_options.start_positions(mesh, "auto", guarded, False, second) for second in (False, True))
    np.testing.assert_array_equal(alone[0], beside[0])
    assert alone[1] == beside[1]


def _slim_worker_started_here(_) -> bool:
    from sim.mesh_io import load_mesh
    from sim import run_options
    from support import SCANS

    run_options.SLIM_BESIDE_ARAP_VERTICES = 1
    with run_options.slim_beside_arap(load_mesh(SCANS / "bunny_ear.obj"), enabled=True) as slim:
        return slim is not None


def test_no_slim_worker_from_a_daemonic_process():
    """springflat.flatten called in a user's multiprocessing.Pool worker, which may not have children."""
    import multiprocessing

    with multiprocessing.get_context("fork").Pool(1) as pool:
        assert pool.map(_slim_worker_started_here, [0]) == [False]


def _sigterm_handler_of_a_worker() -> str:
    return repr(signal.getsignal(signal.SIGTERM))


def test_only_a_pools_own_workers_get_sigterms_default_action():
    """A worker ends at once on SIGTERM (its pool's stop), from its first instruction; a process that a
    program using the API forks itself keeps that program's SIGTERM handler."""
    def mine(signum, frame):
        pass

    before = signal.signal(signal.SIGTERM, mine)
    try:
        read, write = os.pipe()
        child = os.fork()
        if child == 0:  # the program's own child
            os.write(write, (signal.getsignal(signal.SIGTERM) is mine).to_bytes(1, "big"))
            os._exit(0)
        os.close(write)
        kept = os.read(read, 1)
        os.close(read)
        os.waitpid(child, 0)
        with WorkerPool(1) as pool:
            in_worker = pool.submit(_sigterm_handler_of_a_worker).result()
        assert signal.getsignal(signal.SIGTERM) is mine  # and the program's own, after the pool's fork
    finally:
        signal.signal(signal.SIGTERM, before)
    assert kept == b"\x01"
    assert in_worker == repr(signal.SIG_DFL)


@pytest.mark.parametrize("under_the_command", [False, True], ids=["python's-handler", "the-command's"])
def test_a_ctrl_c_while_the_wait_takes_the_futures_locks_leaves_none_held(monkeypatch, under_the_command):
    """``wait`` takes every future's lock in turn; a Ctrl-C between two must not leave one held: the thread
    that completes that future (a pool's, Dask's client loop) would wait on it for ever, and the program with
    it. The signal arrives here between the first lock and the second, and is answered after the slice."""
    from sim.outputs import on_interrupt, when_interrupted

    futures = [Future() for _ in range(3)]

    def take_the_locks_with_a_ctrl_c_between(self):
        first, *rest = self.futures
        first._condition.acquire()
        signal.raise_signal(signal.SIGINT)
        for future in rest:
            future._condition.acquire()

    monkeypatch.setattr(_base._AcquireFutures, "__enter__", take_the_locks_with_a_ctrl_c_between)
    monkeypatch.setattr("sim.outputs._INTERRUPTED", threading.Event())  # (the command's answer notes the signal)
    hooks_ran = []
    before = signal.signal(signal.SIGINT, on_interrupt if under_the_command else signal.default_int_handler)
    try:
        with when_interrupted(lambda: hooks_ran.append(True)), pytest.raises(KeyboardInterrupt):
            wait_for_one(futures)
    finally:
        signal.signal(signal.SIGINT, before)
    completing = [threading.Thread(target=f.set_result, args=(1,), daemon=True) for f in futures]
    for thread in completing:
        thread.start()
        thread.join(5)
    stuck = [i for i, thread in enumerate(completing) if thread.is_alive()]
    for i in stuck:  # (freed, so the thread ends)
        futures[i]._condition.release()
    assert stuck == []
    assert hooks_ran == ([True] if under_the_command else [])  # the command's hooks (Dask's quiet) still run


def test_a_signal_held_through_a_slice_reaches_an_asyncio_program_once():
    """A program that takes SIGINT through asyncio's ``add_signal_handler`` gets a signal that arrived while
    the API held it (a slice of a wait, a set of renames) once: asyncio is told through its wakeup fd,
    which the signal had reached already; raising it again after the slice told asyncio twice."""
    from sim.outputs import deferred_interrupts

    async def program() -> list[str]:
        loop = asyncio.get_running_loop()
        seen: list[str] = []
        loop.add_signal_handler(signal.SIGINT, seen.append, "SIGINT")
        try:
            with deferred_interrupts():
                signal.raise_signal(signal.SIGINT)
            await asyncio.sleep(0.2)
        finally:
            loop.remove_signal_handler(signal.SIGINT)
        return seen

    assert asyncio.run(program()) == ["SIGINT"]


@pytest.mark.parametrize("address, problem", [
    ("foo", "no port"), ("tcp://foo", "no port"), ("tls://foo", "no port"), ("tcp://foo:0", "port 0 is not in 1-65535"),
    ("tcp://foo:8786", None), ("ws://foo", None), ("wss://foo/dask", None),  # a websocket's port is its URL's
])
def test_a_scheduler_address_dask_could_not_connect_to_is_refused_before_the_run(address, problem):
    from golden_model.params import ParameterError
    from sim.workers import check_scheduler_address

    if problem is None:
        check_scheduler_address(address)
    else:
        with pytest.raises(ParameterError, match=rf"^--scheduler '{address}': {problem} \(expected 'local' or "):
            check_scheduler_address(address)


def test_workers_do_not_run_the_callers_script_again_whatever_start_method_it_chose(tmp_path):
    """Under ``spawn`` (macOS's default) or ``forkserver`` (Linux's from Python 3.14) a worker re-imports the
    main module: an API call's hidden SLIM worker ran a caller's unguarded top-level code a second time."""
    script = tmp_path / "script.py"
    script.write_text("import multiprocessing, os\n"
                      "multiprocessing.set_start_method('spawn', force=True)\n"
                      "print('top-level ran', flush=True)\n"
                      "from sim.workers import WorkerPool\n"
                      "with WorkerPool(1) as pool:\n"
                      "    print('worker', pool.submit(os.getpid).result() != os.getpid(), flush=True)\n")
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == ["top-level ran", "worker True"]


def _gone(pid: int) -> bool:
    """Whether the process ``pid`` has ended (a zombie no one has reaped yet counts as ended)."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] in ("Z", "X")
    except FileNotFoundError:
        return True


@pytest.mark.skipif(sys.platform != "linux", reason="PR_SET_PDEATHSIG is Linux's")
def test_a_worker_ends_when_its_parent_is_killed(tmp_path):
    """SIGKILL gives the pool's process no chance to stop its workers, which would wait on its pipe."""
    script = ("import sys, time\nsys.path.insert(0, %r)\nfrom sim.workers import WorkerPool\n"
              "import os\npool = WorkerPool(1)\nprint(pool.submit(os.getpid).result(), flush=True)\n"
              "pool.submit(time.sleep, 600)\ntime.sleep(600)\n") % str(REPO)
    parent = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    worker = None
    try:
        worker = int(parent.stdout.readline())
        assert not _gone(worker)
        parent.kill()
        parent.wait(timeout=30)
        deadline = time.monotonic() + 30
        while not _gone(worker) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert _gone(worker)
    finally:
        parent.kill()
        if worker is not None and not _gone(worker):  # (the check failed: no orphan left behind)
            os.kill(worker, signal.SIGKILL)


def test_a_dask_workers_malloc_trim_threshold_is_undone_before_each_task(monkeypatch):
    """Dask's nanny sets MALLOC_TRIM_THRESHOLD_=65536, which also freezes glibc's mmap threshold: a 22,000-vertex
    flattening took 3x as long on a Dask worker. Where it is set, each batch and study task sets glibc's
    thresholds where its own dynamic ones end (docs/patterns.md, measured with benchmarks/bench_batch.py); where it
    is not, nothing is called."""
    import ctypes

    from sim.workers import undo_dask_malloc_trim

    calls = []

    class Libc:
        def mallopt(self, parameter, value):
            calls.append((parameter, value))
            return 1

    import distributed

    monkeypatch.setattr(ctypes, "CDLL", lambda name: Libc())
    monkeypatch.delenv("MALLOC_TRIM_THRESHOLD_", raising=False)
    undo_dask_malloc_trim()
    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "65536")
    undo_dask_malloc_trim()  # not in a Dask worker: the command's own process, a pool's, an API caller's
    assert calls == []
    monkeypatch.setattr(distributed, "get_worker", lambda: object())  # in a worker's task
    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "1000000")  # the user's own value: theirs
    undo_dask_malloc_trim()
    assert calls == []
    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "65536")
    undo_dask_malloc_trim()
    assert calls == [(-3, 32 << 20), (-1, 64 << 20)]  # M_MMAP_THRESHOLD, M_TRIM_THRESHOLD (malloc.h)
