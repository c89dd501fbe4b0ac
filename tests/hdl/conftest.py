"""Every test here runs its body in a fresh thread, for the speed of Amaranth's simulator.

Why: CPython 3.11 keeps each thread's Python frames in 16 KiB chunks, and a call whose frame does not
fit in what is left of the current chunk gets a chunk of its own, mapped before the call and unmapped
after it. Amaranth's simulator calls a generated function with thousands of locals at every clock;
where the test's stack is deep enough (a pytest-xdist worker, as in ``make test``), that function
lands past the chunk's end, and every call maps and unmaps one. Measured on the node update's
random-degree test (default formats): 1.36 million ``mmap``/``munmap`` pairs and 20 s in a worker, 3 s
run directly; in a fresh thread, whose stack starts empty, 2.3 s in the worker. The engine's whole runs
are not affected (the same time in either case).
"""

from __future__ import annotations

import inspect
import threading

import pytest


@pytest.hookimpl(tryfirst=True)
def pytest_pyfunc_call(pyfuncitem: pytest.Function) -> bool:
    """Call the test function, with its fixtures' values, in a new thread and wait for it; an exception
    (a failed assertion, ``pytest.skip``) is raised again here, with its traceback."""
    function = pyfuncitem.obj
    arguments = {name: pyfuncitem.funcargs[name] for name in inspect.signature(function).parameters
                 if name in pyfuncitem.funcargs}
    raised: list[BaseException] = []

    def body() -> None:
        try:
            function(**arguments)
        except BaseException as exc:  # noqa: BLE001 - handed to the test's own thread
            raised.append(exc)

    thread = threading.Thread(target=body, name=f"test {pyfuncitem.name}")
    thread.start()
    thread.join()
    if raised:
        raise raised[0]
    return True
