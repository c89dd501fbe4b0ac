"""Wishbone initiator helpers for Amaranth's simulator (the bus of :mod:`hdl.wishbone`).

:func:`wishbone_cycle` runs one classic cycle and returns the target's answer; the cocotb benches
drive the same protocol from their side (:mod:`sim.cocotb_benches`). Random idle clocks between
cycles (``idle``) are the initiator's wait states; the target's come from its own latency.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["BusAnswer", "wishbone_cycle", "wishbone_write", "wishbone_read"]


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
