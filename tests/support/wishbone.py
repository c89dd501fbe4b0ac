"""Wishbone initiator helpers for Amaranth's simulator (the bus of :mod:`hdl.wishbone`).

:func:`wishbone_cycle` runs one classic cycle and returns the target's answer; the cocotb benches
drive the same protocol from their side (:mod:`sim.cocotb_benches`). Random idle clocks between
cycles (``idle``) are the initiator's wait states; the target's come from its own latency.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["BusAnswer", "wishbone_cycle", "wishbone_write", "wishbone_read", "ThreadedBus"]


@dataclass(frozen=True)
class BusAnswer:
    """A target's answer to one cycle: ``ack`` or ``err``, the read data, the clocks it took."""

    error: bool
    data: int
    clocks: int


async def wishbone_cycle(ctx, bus, adr: int, *, write: bool, data: int = 0, sel: int | None = None,
                         idle: int = 0, timeout: int = 10_000, keep_stb: bool = False) -> BusAnswer:
    """One classic cycle after ``idle`` clocks with ``cyc`` low: hold the request until ``ack`` or
    ``err``. ``sel`` defaults to all ones. With ``keep_stb`` the cycle's signals stay asserted on
    return (so the caller can present the next request back to back), else they drop."""
    for _ in range(idle):
        ctx.set(bus.cyc, 0)
        ctx.set(bus.stb, 0)
        await ctx.tick()
    ctx.set(bus.cyc, 1)
    ctx.set(bus.stb, 1)
    ctx.set(bus.we, int(write))
    ctx.set(bus.adr, adr)
    ctx.set(bus.dat_w, data)
    ctx.set(bus.sel, (1 << len(bus.sel)) - 1 if sel is None else sel)
    for clocks in range(1, timeout + 1):
        _, _, ack, err, dat_r = await ctx.tick().sample(bus.ack, bus.err, bus.dat_r)
        if ack or err:
            if not keep_stb:
                ctx.set(bus.cyc, 0)
                ctx.set(bus.stb, 0)
            return BusAnswer(bool(err), int(dat_r), clocks)
    raise TimeoutError(f"no ack/err for address {adr:#x} within {timeout} clocks")


async def wishbone_write(ctx, bus, adr: int, data: int, **kwargs) -> BusAnswer:
    return await wishbone_cycle(ctx, bus, adr, write=True, data=data, **kwargs)


async def wishbone_read(ctx, bus, adr: int, **kwargs) -> BusAnswer:
    return await wishbone_cycle(ctx, bus, adr, write=False, **kwargs)


class ThreadedBus:
    """A blocking ``read``/``write`` bus (the :class:`sim.engine_driver.Bus` protocol) for a host
    driver running in a thread, served by an Amaranth testbench (:meth:`serve`).

    The driver is synchronous (it is also used with cocotb and with a pure-Python model); the
    simulator's testbenches are coroutines. :meth:`serve` takes the driver's requests from a queue
    and runs each as a Wishbone cycle; ``idle(n)`` lets the driver wait ``n`` clocks (a poll). The
    simulated time stands still between requests, so a run's clocks do not depend on the threads.
    """

    def __init__(self, error: type[Exception] = RuntimeError, wait_states=None):
        import queue

        self._requests: "queue.Queue" = queue.Queue()
        self._answers: "queue.Queue" = queue.Queue()
        self._error = error
        self._wait_states = wait_states or (lambda: 0)
        self.cycles = 0

    def _call(self, request):
        self._requests.put(request)
        answer = self._answers.get()
        if isinstance(answer, BaseException):
            raise answer
        return answer

    def read(self, address: int) -> int:
        return self._call(("read", address, 0))

    def write(self, address: int, value: int) -> None:
        self._call(("write", address, value))

    def idle(self, clocks: int) -> None:
        self._call(("idle", clocks, 0))

    def in_simulator(self, action) -> None:
        """Run ``action(ctx)`` in the testbench, between two clocks (e.g. ``ctx.set`` on a memory's rows)."""
        self._call(("call", action, 0))

    def run(self, host) -> None:
        """Run ``host()`` (the driver's calls) in a thread; :meth:`serve` ends when it returns."""
        import threading

        def body():
            try:
                host()
                self._requests.put(("done", None, None))
            except BaseException as exc:  # handed to the testbench, which re-raises it
                self._requests.put(("failed", exc, None))

        self._thread = threading.Thread(target=body, daemon=True)
        self._thread.start()

    async def serve(self, ctx, bus) -> None:
        """Serve requests until the host is done (re-raising its exception).

        The simulator waits for each request rather than ticking while the host thread works: the
        clocks between two requests are exactly the ones the driver asks for (``idle``) and the
        answers' own, whatever the threads' scheduling, and no clock is simulated for a host that is
        only computing its next word (ticking meanwhile, most of an engine load's clocks would be the host's)."""
        while True:
            kind, a, b = self._requests.get()
            if kind == "done":
                return
            if kind == "failed":
                raise a
            if kind == "idle":
                await ctx.tick().repeat(a)
                self._answers.put(None)
                continue
            if kind == "call":
                a(ctx)
                self._answers.put(None)
                continue
            answer = await wishbone_cycle(ctx, bus, a, write=kind == "write", data=b, idle=self._wait_states())
            self.cycles += answer.clocks
            if answer.error:
                self._answers.put(self._error(f"bus error: {kind} at word address {a:#x} answered err"))
            else:
                self._answers.put(answer.data if kind == "read" else None)
