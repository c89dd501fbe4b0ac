"""SATURATIONS: the run's saturation events, summed in registered stages, stopping at the maximum."""

from __future__ import annotations

from amaranth.hdl import Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from .logic import reset_echo
from .parameters import check_int

__all__ = ["SaturationTally"]


class SaturationTally(wiring.Component):
    """Adds the units' saturation events to a count that stops at its maximum (never wraps).

    Parameters
    ----------
    sources : dict of str to int
        The event inputs, in order, and their widths; an even number (they are summed in pairs).
    count_bits : int
        Width of the count.
    overflow_bits : bool
        The count kept in a register wider than ``count_bits`` (by one bit, or more where one clock's
        events are wider): a sum past the maximum sets its high bits, which then hold the count still
        (their OR is its clock enable), and ``saturations`` is the low bits ORed with them. The adder's
        carry chain then ends in the count's own flip-flops, with no multiplexer after it whose select,
        the chain's carry-out, fans out to every bit (the engine's builds above ``DEFAULT_CAPACITY``).
        The same count in every clock.

    Members
    -------
    ``<source>_events`` : ``In(width)``, one per source
        Events reported this clock (0 when there is none).
    clear : ``In(1)``
        Restart the count from 0 (a new run); it takes precedence over the clock's events.
    saturations : ``Out(count_bits)``
        The count.
    saturated : ``Out(1)``
        ``saturations != 0``, a clock later (registered: a wide OR off the register read path).

    Latency
    -------
    Each event lands in a register, the pairs' sums in registers of their own, their sum in another,
    then the count: an event reported at clock t is in ``saturations`` after the edge at t + 4 (and in
    ``saturated`` one later). The stages are registered because summing every source into the wide
    saturating add in one clock is a long carry chain behind a wide adder tree.
    """

    def __init__(self, sources: dict[str, int], *, count_bits: int, overflow_bits: bool = False):
        sources = dict(sources)
        if not sources or len(sources) % 2:
            raise ValueError(f"SaturationTally sums its sources in pairs: it needs an even number, not {len(sources)}")
        for name, width in sources.items():
            if not name.isidentifier():
                raise ValueError(f"event source {name!r}: its name must be an identifier")
            check_int(f"event source {name!r}'s width", width)
        check_int("count_bits", count_bits)
        if not isinstance(overflow_bits, bool):
            raise TypeError(f"SaturationTally overflow_bits must be a bool, not {overflow_bits!r}")
        self.overflow_bits = overflow_bits
        #: Width of the sum of one clock's events (the pairs' sums, then their sum).
        self.events_bits = max(sources.values()) + (len(sources) - 1).bit_length()
        self.sources, self.count_bits = sources, count_bits
        super().__init__({
            **{f"{name}_events": In(width) for name, width in sources.items()},
            "clear": In(1), "saturations": Out(count_bits), "saturated": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        event_regs = [Signal(width, name=f"saturation_event{k}") for k, width in enumerate(self.sources.values())]
        m.d.sync += [r.eq(getattr(self, f"{name}_events")) for r, name in zip(event_regs, self.sources)]
        new_events = Signal(self.events_bits, name="new_events")
        pair_sums = [Signal(max(self.sources.values()) + 1, name=f"saturation_pair{k}")
                     for k in range(len(event_regs) // 2)]
        m.d.sync += [p.eq(event_regs[2 * k] + event_regs[2 * k + 1]) for k, p in enumerate(pair_sums)]
        m.d.sync += new_events.eq(sum(pair_sums))
        # the count has no domain reset: `clear` and the reset's echo clear it (a LUT of the domain's
        # reset and `clear` driving its reset pins is a long path on the board)
        if self.overflow_bits:
            self._count_with_overflow_bits(m, new_events)
            return m
        count = Signal.like(self.saturations, reset_less=True, name="count")
        m.d.comb += self.saturations.eq(count)
        # past the maximum exactly when the sum has a bit set above the count's width: an OR of those
        # bits chooses, not a compare (a second carry chain after the adder's, on the count's loop)
        total = count + new_events
        saturation_max = (1 << len(count)) - 1
        m.d.sync += count.eq(Mux(total[len(count):].any(), saturation_max, total[:len(count)]))
        with m.If(self.clear | reset_echo(m, "count_echo")):
            m.d.sync += count.eq(0)
        m.d.sync += self.saturated.eq(count != 0)
        return m

    def _count_with_overflow_bits(self, m: Module, new_events: Signal) -> None:
        """The count below the maximum in the low bits, past it a high bit set and the count held. Adding a
        clock's events (below ``2**events_bits``) to a count below ``2**count_bits`` cannot carry out of a
        register one bit wider than the wider of the two."""
        width = max(self.count_bits, self.events_bits) + 1
        count = Signal(width, reset_less=True, name="count_wide")
        over = count[self.count_bits:].any()
        with m.If(~over):
            m.d.sync += count.eq(count + new_events)
        with m.If(self.clear | reset_echo(m, "count_echo")):
            m.d.sync += count.eq(0)
        m.d.comb += self.saturations.eq(count[:self.count_bits] | over.replicate(self.count_bits))
        m.d.sync += self.saturated.eq(self.saturations != 0)
