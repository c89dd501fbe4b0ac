"""The lanes' passes joined: a pass ends when every lane's has, and its sums are the lanes' sums."""

from __future__ import annotations

from amaranth.hdl import Cat, Module, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from golden_model.engine_spec.image import EngineCapacity
from golden_model.fixed import FormatSet

from .fixedpoint import clamp, shape_of
from .layouts import pass_sum_shapes

__all__ = ["LaneSums", "LANE_PASSES", "LANE_SUMS"]

#: The passes each lane runs on its share, in the order their ends are joined.
LANE_PASSES = ("force", "area", "integrate")
#: Each pass's exact sums (the area pass's is the area units' ``total``).
LANE_SUMS = {"force": ("length_sum", "square_sum", "barrier_sum"), "area": ("area_total",), "integrate": ("power_sum",)}


class LaneSums(wiring.Component):
    """The K lanes' ends of a pass joined into one, and their sums added, for the one controller.

    Every sum of a pass is exact (the area units' running sums saturate at ``error_acc``'s maximum, which
    for non-negative terms is the exact sum saturated once), so the lanes' sums add up to one lane's sum of
    the whole mesh, and a saturation event of a whole sum (E_C's ``length_sum``, S's ``power_acc``, E_S's
    ``area_sum``) is decided on the lanes' sum: ``golden_model.fixed.measures`` counts it once per pass.

    Parameters
    ----------
    fs : :class:`~golden_model.fixed.FormatSet`
    capacity : :class:`~golden_model.engine_spec.image.EngineCapacity`
        Its ``lanes`` (K > 1) and the widths of the sums (those of one lane over the whole capacity).

    Members
    -------
    ``<pass>_done_in`` : ``In(1).array(K)``; ``<pass>_done`` : ``Out(1)``
        A lane's pass end (a one-clock pulse, once per pass: :class:`~hdl.pass_sequencer.PassSequencer`'s), for
        ``force``, ``area`` and ``integrate``; the pass's end, a one-clock pulse two clocks after the last lane's
        (each lane's end is registered first).
    ``<sum>_in`` : ``In(...).array(K)``; ``<sum>`` : ``Out(...)``
        Each lane's sum, whole from its pass end until the next pass restarts it; the lanes' sum, a register
        loaded with the pass end (``length_sum``, ``square_sum``, ``barrier_sum``, ``power_sum``, and
        ``area_total``, ``error_acc`` saturated).
    area_saturated_in : ``In(1).array(K)``
        Each area unit's ``saturations.area_sum`` (its running sum saturated).
    restart : ``In(1)``
        The start phase: forget the lanes seen so far (a run aborted in a pass).
    momentum : ``In(1)``
        A momentum mode: S's saturation counts.
    length_events, power_events, area_events : ``Out(1)``
        The whole sums' saturation events, with the pass end (``power_events`` only with ``momentum``).
    """

    def __init__(self, fs: FormatSet, capacity: EngineCapacity):
        if not isinstance(fs, FormatSet) or not isinstance(capacity, EngineCapacity):
            raise TypeError(f"LaneSums needs a FormatSet and an EngineCapacity, not {fs!r}, {capacity!r}")
        if capacity.lanes < 2:
            raise ValueError(f"LaneSums joins two lanes or more, not {capacity.lanes}")
        self.fs, self.lanes = fs, capacity.lanes
        self.sum_shapes = {**pass_sum_shapes(fs, capacity.vertices, capacity.entries),
                           "area_total": shape_of(fs.error_acc)}
        super().__init__({
            **{f"{name}_done_in": In(1).array(self.lanes) for name in LANE_PASSES},
            **{f"{name}_done": Out(1) for name in LANE_PASSES},
            **{f"{name}_in": In(shape).array(self.lanes) for name, shape in self.sum_shapes.items()},
            **{name: Out(shape) for name, shape in self.sum_shapes.items()},
            "area_saturated_in": In(1).array(self.lanes), "restart": In(1), "momentum": In(1),
            "length_events": Out(1), "power_events": Out(1), "area_events": Out(1),
        })

    def elaborate(self, platform):
        fs, lanes = self.fs, self.lanes
        m = Module()
        area_over = Signal(name="area_over")
        for name in LANE_PASSES:
            # each lane's end landed beside the join first: the lanes' sequencers sit across the device, and their
            # pulses into the seen flags' logic were its critical path
            ends = Signal(lanes, name=f"{name}_ends")
            m.d.sync += ends.eq(Cat(*getattr(self, f"{name}_done_in")))
            seen = Signal(lanes, name=f"{name}_seen")
            now = Cat(seen[k] | ends[k] for k in range(lanes))
            every = now.all()
            m.d.sync += getattr(self, f"{name}_done").eq(every)
            with m.If(every | self.restart):
                m.d.sync += seen.eq(0)
            with m.Else():
                m.d.sync += seen.eq(now)
            with m.If(every):
                for sum_name in LANE_SUMS[name]:
                    total = sum(getattr(self, f"{sum_name}_in"))
                    if sum_name == "area_total":
                        total, over = clamp(total, fs.error_acc)
                        m.d.sync += area_over.eq(over | Cat(*self.area_saturated_in).any())
                    m.d.sync += getattr(self, sum_name).eq(total)
        power = self.power_sum
        m.d.comb += [
            self.length_events.eq(self.force_done & (self.length_sum > fs.error_acc.raw_max)),
            self.power_events.eq(self.integrate_done & self.momentum
                                 & ((power > fs.power_acc.raw_max) | (power < fs.power_acc.raw_min))),
            self.area_events.eq(self.area_done & area_over),
        ]
        return m
