"""The top-level core: the node-update datapath with its step generator and step registers."""

from __future__ import annotations

from amaranth.hdl import Module, Mux
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out, connect

from golden_model.fixed import FormatSet

from .fixedpoint import shape_of
from .layouts import entry_layout, errors_layout, result_layout, step_layout
from .node_update import NodeUpdate
from .stepgen import StepGenerator, stepgen_idle_signal

__all__ = ["SpringflatCore"]


class SpringflatCore(wiring.Component):
    """Node-update datapath + exp-LUT step generator + the step registers between them.

    Members
    -------
    entries : ``In(stream.Signature(entry_layout(fs)))``
        Neighbour entries (see :class:`~hdl.node_update.NodeUpdate`).
    results : ``Out(stream.Signature(result_layout(fs)))``
        One result per node.
    errors : ``In(stream.Signature(errors_layout(fs)))``
        E_S and E_C of the current layout; the step generator turns them into
        ``Δt, ½Δt²``, which load the step registers (variable step).
    step_load : ``In(stream.Signature(step_layout(fs)))``
        Loads the step registers directly (fixed step). Always ready.
    step : ``Out(step_layout(fs))``
        The step registers.
    step_valid : ``Out(1)``
        The step registers hold the answer to the last ``errors`` accepted: low from that
        transfer until the step generator's result loads them (``step_latency`` clocks), high
        after reset and after a ``step_load``. A controller waits for it instead of counting.
    idle : ``Out(1)``
        No entry is in flight (:attr:`hdl.node_update.NodeUpdate.idle`): every node accepted has
        left ``results``, so a pass is done and ``step``/``measure`` and the constants may change.
    measure : ``In(1)``
        While high the datapath sees ``Δt = ½Δt² = 0`` and ``1 − γ = 1``: a pass that moves
        nothing and yields the E_C partial sums of the current positions.
    half_spring, damping : ``In(...)``
        ``½C`` [spring] and ``1 − γ`` [damping].
    momentum : ``In(1)``
        The momentum dynamics (the step registers then hold ``β`` in ``dt``, loaded through
        ``step_load``); a measure pass runs the paper's step with ``Δt = 0`` in either mode,
        so it moves nothing and yields E_C partial sums and the power ``F·V``.

    Contract: ``entries``/``results`` as :class:`~hdl.node_update.NodeUpdate` (II = 1 entry per
    clock, latency ``latency``); ``errors`` → ``step`` takes ``step_latency`` clocks (``step_valid``
    says when). Change ``step``/``measure``/``half_spring``/``damping`` only while ``idle``.
    """

    def __init__(self, fs: FormatSet | str):
        if isinstance(fs, str):
            fs = FormatSet.preset(fs)
        if not isinstance(fs, FormatSet):
            raise TypeError(f"SpringflatCore needs a FormatSet or a preset name, not {fs!r}")
        self.fs = fs
        self._datapath = NodeUpdate(fs)
        self._stepgen = StepGenerator(fs)
        self.latency = self._datapath.latency
        self.credits, self.result_depth = self._datapath.credits, self._datapath.result_depth
        self.step_latency = self.step_latency_of(fs)
        super().__init__({
            "entries": In(stream.Signature(entry_layout(fs))),
            "results": Out(stream.Signature(result_layout(fs))),
            "errors": In(stream.Signature(errors_layout(fs))),
            "step_load": In(stream.Signature(step_layout(fs))),
            "step": Out(step_layout(fs)),
            "step_valid": Out(1),
            "idle": Out(1),
            "measure": In(1),
            "half_spring": In(shape_of(fs.spring)),
            "damping": In(shape_of(fs.damping)),
            "momentum": In(1),
        })

    @staticmethod
    def step_latency_of(fs: FormatSet) -> int:
        """Clocks from an ``errors`` transfer to ``step_valid``: the step generator's latency and the
        register that loads ``step`` (no component is built)."""
        return StepGenerator.latency_of(fs) + 1

    def elaborate(self, platform):
        fs = self.fs
        m = Module()
        m.submodules.datapath = datapath = self._datapath
        m.submodules.stepgen = stepgen = self._stepgen
        connect(m, wiring.flipped(self.entries), datapath.i)
        connect(m, datapath.o, wiring.flipped(self.results))
        connect(m, wiring.flipped(self.errors), stepgen.i)

        m.d.comb += [stepgen.o.ready.eq(1), self.step_load.ready.eq(1), self.idle.eq(datapath.idle)]
        with m.If(self.step_load.valid):
            m.d.sync += self.step.eq(self.step_load.payload)
        with m.Elif(stepgen.o.valid):
            m.d.sync += [self.step.dt.eq(stepgen.o.payload.dt), self.step.half_dt_sq.eq(stepgen.o.payload.half_dt_sq)]
        # the registers are valid when no request is pending in the step generator
        m.d.comb += self.step_valid.eq(stepgen_idle_signal(m, stepgen))

        one = 1 << fs.damping.frac_bits  # 1 − γ = 1 exactly: the damping multiply is then exact
        m.d.comb += [
            datapath.dt.eq(Mux(self.measure, 0, self.step.dt)),
            datapath.half_dt_sq.eq(Mux(self.measure, 0, self.step.half_dt_sq)),
            datapath.damping.eq(Mux(self.measure, one, self.damping)),
            datapath.half_spring.eq(self.half_spring),
            datapath.momentum.eq(self.momentum & ~self.measure),
        ]
        return m
