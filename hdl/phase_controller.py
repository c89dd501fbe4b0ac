"""The engine's phase controller: a run from START to its result, one phase flip-flop at a time, and the
once-per-iteration arithmetic it runs between the passes (normalisers, energy check, the step)."""

from __future__ import annotations

from dataclasses import dataclass

from amaranth.hdl import C, Cat, Module, Mux, Signal, Value
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from golden_model.fixed import FormatSet
from golden_model.modes import Step
from golden_model.engine_spec.image import ITERATION_BITS
from golden_model.guard import SCALE_MAX_SHIFT
from golden_model.engine_spec.register_map import RESULTS, STATES, RegisterMap

from .controller_units import BetaDivider, EnergyCheck, Normaliser
from .guard_decision import SPLIT_RISE_PARTS, GuardDecision
from .guard_passes import GUARD_PASSES
from .dsp import kept_register, registered_product
from .fixedpoint import clamp, shape_of, shift_round
from .layouts import pass_sum_shapes
from .logic import mode_guarded, mode_runs, mode_steps, or_tree, reset_echo
from .pass_sequencer import FETCH_FLAGS
from .stepgen import StepGenerator, pending_is_zero

__all__ = ["PhaseController", "PHASES", "COARSE_PHASES", "phases_of"]

#: The phases of a run, in code order (the ``phase`` debug code).
PHASES = ("start", "force", "area", "math", "decide", "check", "step", "step_wait", "integrate", *GUARD_PASSES, "drain")
#: The phases a build with a coarse space has besides :data:`PHASES` (their codes follow those): the coarse
#: space's sums pass and coefficients (:class:`~hdl.coarse_passes.CoarsePasses`).
COARSE_PHASES = ("coarse",)


def phases_of(capacity) -> tuple[str, ...]:
    """The phases of a build of ``capacity``, in code order."""
    return PHASES + (COARSE_PHASES if capacity.coarse_degree else ())

#: Run constants the controller reads from the register bank, and those it reads from their copies.
CONSTANTS = ("vertices", "entries", "triangles", "mode", "dt", "max_iter", "saturation_limit",
             "tol_area", "tol_shape", "area_reciprocal", "area_shift", "length_reciprocal", "length_shift",
             "energy_floor")
HELD = ("area_reciprocal", "area_shift", "length_reciprocal", "length_shift", "half_spring", "tol_energy")

#: Results the controller holds (the register map's values).
RESULT_VALUES = ("iterations", "area_error", "shape_error", "cycles", "energy")


def _code(codes: tuple[str, ...], name: str) -> int:
    return codes.index(name)


def _registered(m: Module, value, name: str) -> Signal:
    """``value`` a clock later, in a flip-flop of its own."""
    q = Signal(name=name)
    m.d.sync += q.eq(value)
    return q


@dataclass
class _Run:
    """The controller's internal registers, shared by its parts."""

    first_measure: Signal
    math_pending: Signal
    settled: Signal
    fixed_load: Signal
    fixed_half: Signal
    momentum_k: Signal
    momentum: Signal  # MODE.mode selects the momentum step (registered)
    fixed_step: Signal  # MODE.mode selects the fixed step (registered)
    guarded: Value  # MODE.mode selects the guarded step (registered; 0 in a build without the guard)
    measuring_again: Signal  # the accepted layout measured again after a rollback (its events not counted)
    stalled: Signal  # the decision's: the step scale passed SCALE_MAX_SHIFT
    abort: Signal  # CONTROL.abort registered once more, beside the phase machine
    abort_guard: Signal | None  # with control copies, a copy of ``abort`` for the transitions that wait on the guard
    abort_passes: Signal | None  # with control copies, a copy of ``abort`` for those that wait on a pass's end
    requests: dict  # {unit name: a pulse, the phase machine's request, which sets the unit's input valid}


class PhaseController(wiring.Component):
    """Algorithm 1's control: the run's state and phases, its stop decisions and its arithmetic units.

    A run goes start → force → area → math → check, then step → step_wait → integrate → start again
    until the check phase stops it (diverged, converged, at N_max); ABORT while running drains what is
    in flight and goes idle. Its units (:class:`~hdl.controller_units.Normaliser` ×2,
    :class:`~hdl.controller_units.EnergyCheck`, :class:`~hdl.controller_units.BetaDivider`,
    :class:`~hdl.stepgen.StepGenerator`) are submodules of its own: it alone feeds and reads them.

    Parameters
    ----------
    fs : :class:`~golden_model.fixed.FormatSet`
    register_map : :class:`~golden_model.engine_spec.register_map.RegisterMap`
        Sizes the constants' and results' ports (its values) and the energy check (its capacity).
    registered_verdict : bool
        The check phase's verdict (a result, or the step) in flip-flops of their own, taken from the
        phase's first clock and acted on in its second: a clock more per check, so that the phase flags,
        placed by the units they drive across the device, are set from registers through no more than
        a LUT or two (the engine's builds above ``DEFAULT_CAPACITY``; ``docs/synthesis.md``). The guard
        decision's rise is then compared in :data:`~hdl.guard_decision.SPLIT_RISE_PARTS` parts and joined
        a clock later (a clock more per guarded iteration), and the energy check loads ``ε·E_prev`` from a
        copy of its energy phase's flag (``EnergyCheck(load_copy=True)``).
    control_copies : bool
        ABORT's register copied, each copy loaded from the same pulse (so equal to it in every clock):
        one for the transitions that wait on the guard's passes, one for those that wait on a pass's
        end, each placed by its own group of loads rather than at the centre of all of them; and
        ``running_next`` exported, from which a port's copy of ``running`` is loaded; and the momentum step's
        pulse, which moves ``k``, is the β request's flip-flop (loaded from the same condition in the same
        clock), so that the step phase's logic has no load across the device from the phase machine (the
        engine's builds above ``DEFAULT_CAPACITY``).

    Members
    -------
    start, abort : ``In(1)``
        CONTROL's pulses (registered in the register bank). ABORT is registered once more here: a run
        under way drains from the clock after the pulse; a write that sets both is not a start.
    the run constants of :data:`CONSTANTS` : ``In``; ``<name>_held`` of :data:`HELD` : ``In``
        As the register bank holds them; the held copies are read by the units.
    saturations : ``In``
        SATURATIONS (:class:`~hdl.saturation_tally.SaturationTally`).
    force_done, area_done, integrate_done : ``In(1)``
        From the :class:`~hdl.pass_sequencer.PassSequencer`.
    passes_idle : ``In(1)``
        Registered: in the clock before, every pass had fetched its last item and none was in a
        fetch, a unit or a guard pass (the sequencer's and the guard's ``passes_idle`` and ``idle``).
    length_sum, square_sum, barrier_sum, power_sum, area_total : ``In``
        The passes' sums (``area_total`` from :class:`~hdl.area_error.AreaError`; with lanes, the pass ends
        and sums from :class:`~hdl.lanes.LaneSums`).
    lane_fault : ``In(1)``
        With K > 1 lanes only: LANEk_ENTRIES do not add up to ENTRIES or one overflows its share (START
        answers ``bad-constants``).
    state, result, running : ``Out``
        STATUS.state and STATUS.result codes; ``running`` is ``state == running`` as a flip-flop of
        its own (it gates every pass, port multiplexer and bus answer: their logic starts from a
        register rather than a compare).
    running_next : ``Out(1)``
        With ``control_copies`` only: combinational, ``running``'s next value (the domain's reset aside): a
        register loaded from it and cleared by the reset is a copy of ``running``.
    starting, irq_set : ``Out(1)``
        Combinational: START accepted this clock (the results and STATUS.irq_pending restart); a
        run ends this clock (STATUS.irq_pending set).
    coarse : ``In(1)``, coarse_done : ``In(1)``, coarse_step : ``Out(1)``, coarse_clipped : ``In(1)``
        With a coarse space only (``capacity.coarse_degree``): COARSE (the run takes the coarse move), the
        coarse passes' end (:class:`~hdl.coarse_passes.CoarsePasses`), and the guard decision's schedule: the
        coming step takes the move; ``coarse_clipped``: the last commit pass clipped a node deep
        (:class:`~hdl.guard_passes.GuardPasses`' ``clipped``), read with the decision on that step. A guarded
        iteration whose step takes the move runs the ``coarse`` phase, a node pass with the coefficients after
        it, between the check and the step.
    ``in_<phase>`` for each of :data:`PHASES` (and :data:`COARSE_PHASES` with a coarse space) : ``Out(1)``
        One flip-flop per phase, all low while no run is under way (each implies ``running``).
    fetch_force, fetch_area, fetch_nodes, area_clear : ``Out(1)``
        The passes' enables (:class:`~hdl.pass_sequencer.PassSequencer`) and the area unit's clear.
    step_dt, step_half : ``Out``
        The step's ``Δt`` and ``½Δt²`` for the integrator, loaded in the step phases.
    iterations, area_error, shape_error, cycles, energy : ``Out``
        The results (the register map's values).
    step_events, shape_error_events, area_error_events : ``Out``
        The units' saturation events (0 when there is none).
    phase, math_pending : ``Out``
        For a testbench: the phase's code (nothing reads it) and the math results still to come.

    Timing
    ------
    Every decision is taken from flip-flops: the check phase's stop rule, iteration limit and
    saturation limit are compares registered the clock before they are read (the check phase follows
    every pass and unit), START's check of the constants is two registered stages (START's pulse
    comes at least six clocks after a constant's write); the passes' ends come registered from the
    sequencer, and the units' answers the phase machine waits for are registered beside it (the
    decision's a clock after the unit's output, the step's two). A transition clears the phase flag
    it leaves and sets the one it enters, so a flag's next value depends only on the blocks that
    enter or leave it and on ABORT (from a register beside the phase machine, which the pulse from
    the register bank reaches in a clock of its own; START's acceptance, likewise, sets the run's
    state and a register that enters the start phase a clock later; the flags are flip-flops because
    a phase code, or every transition writing every flag, takes the whole phase machine and
    ``running``'s fan-out into each flag's logic). The wide
    registers (ITERATIONS, ``momentum_k``) move on registered pulses the clock after their phase's
    block, and ``restart_pending`` on pulses of its own: no control LUT drives both a wide register
    and a control flag.
    """

    #: Clocks the check phase waits after the math phase's last result: the saturation tally's
    #: pipeline (event, pair sums, their sum, the count) and the registered limit compare, so a
    #: normaliser's saturation is counted before the limit is tested, as in ``run_image``.
    CHECK_SETTLE_CLOCKS = 3

    def __init__(self, fs: FormatSet, register_map: RegisterMap, *, registered_verdict: bool = False,
                 control_copies: bool = False):
        if not isinstance(fs, FormatSet) or not isinstance(register_map, RegisterMap):
            raise TypeError(f"PhaseController needs a FormatSet and a RegisterMap, not {fs!r}, {register_map!r}")
        for flag, value in (("registered_verdict", registered_verdict), ("control_copies", control_copies)):
            if not isinstance(value, bool):
                raise TypeError(f"PhaseController {flag} must be a bool, not {value!r}")
        self.fs, self.capacity = fs, register_map.capacity
        self.registered_verdict, self.control_copies = registered_verdict, control_copies
        self.coarse_built = coarse = bool(self.capacity.coarse_degree)
        #: The phases, in code order (:func:`phases_of`).
        self.phases = phases = phases_of(self.capacity)
        width = register_map.value_width
        #: Width of each saturation-event output.
        self.event_widths = {"step": StepGenerator.output_layout(fs, True)["saturations"].shape.width,
                             "shape_error": 1, "area_error": 1}
        super().__init__({
            "start": In(1), "abort": In(1),
            **{name: In(width(name)) for name in CONSTANTS},
            **{f"{name}_held": In(width(name)) for name in HELD},
            "saturations": In(width("saturations")),
            "force_done": In(1), "area_done": In(1), "integrate_done": In(1), "guard_done": In(1),
            "passes_idle": In(1),
            **{name: In(shape) for name, shape in
               pass_sum_shapes(fs, self.capacity.vertices, self.capacity.entries).items()},
            "area_total": In(shape_of(fs.error_acc)),
            # with lanes, LANEk_ENTRIES that do not add up to ENTRIES or overflow a share (the engine's compare)
            **({"lane_fault": In(1)} if self.capacity.lanes > 1 else {}),
            "state": Out(range(len(STATES)), init=_code(STATES, "idle")),
            "result": Out(range(len(RESULTS)), init=_code(RESULTS, "none")),
            "running": Out(1),
            **({"running_next": Out(1)} if control_copies else {}),
            "starting": Out(1), "irq_set": Out(1),
            **{f"in_{name}": Out(1) for name in phases},
            **({"coarse": In(1), "coarse_done": In(1), "coarse_step": Out(1), "coarse_clipped": In(1)}
               if coarse else {}),
            **{name: Out(1) for name in FETCH_FLAGS}, "area_clear": Out(1),
            "half_rate": Out(1), "node_restart": Out(1), "triangle_restart": Out(1), "guarded": Out(1),
            "measuring_again": Out(1), "scale_shift": Out(range(SCALE_MAX_SHIFT + 2)),
            "step_dt": Out(shape_of(fs.dt)), "step_half": Out(shape_of(fs.half_dt_sq)),
            **{name: Out(width(name)) for name in RESULT_VALUES},
            **{f"{name}_events": Out(w) for name, w in self.event_widths.items()},
            "phase": Out(range(len(phases))), "math_pending": Out(3),
        })

    def elaborate(self, platform):
        m = Module()
        fs, cap = self.fs, self.capacity
        units = {
            "norm_length": Normaliser(fs, saturations=True),
            "norm_area": Normaliser(fs, saturations=True),
            "energy_check": EnergyCheck(fs, cap.entries, load_copy=self.registered_verdict),
            # k counts iterations since the last restart, so it never exceeds ITERATIONS: as wide, it never wraps
            "beta": BetaDivider(fs, k_bits=ITERATION_BITS),
            "stepgen": StepGenerator(fs, saturations=True),
        }
        units["decision"] = GuardDecision(units["energy_check"].energy_bits,
                                          rise_parts=SPLIT_RISE_PARTS if self.registered_verdict else 1,
                                          coarse=self.coarse_built)
        for name, unit in units.items():
            m.submodules[name] = unit
        # the register is as wide as the energy check's tolerance (both from the golden model's
        # ENERGY_TOL_* bits), so every value START sees is valid
        assert len(self.tol_energy_held) == len(units["energy_check"].tolerance)
        phase_codes = [Mux(getattr(self, f"in_{name}"), k, 0) for k, name in enumerate(self.phases)]
        m.d.comb += self.phase.eq(or_tree(phase_codes))

        run = _Run(first_measure=Signal(name="first_measure"), math_pending=self.math_pending,
                   settled=Signal(name="settled"), fixed_load=Signal(name="fixed_load"),
                   fixed_half=self._fixed_half_dt_sq(m, platform), momentum_k=Signal(ITERATION_BITS, name="momentum_k"),
                   momentum=Signal(name="mode_momentum"), fixed_step=Signal(name="mode_fixed_step"),
                   guarded=Signal(name="mode_guarded") if self.capacity.guard else C(0, 1),
                   measuring_again=self.measuring_again,
                   stalled=Signal(name="stalled"), abort=Signal(name="abort_q"), abort_guard=None, abort_passes=None,
                   requests={name: Signal(name=f"{name}_request") for name in units})
        # ABORT registered here: the register bank's pulse is routed across the device, and every phase
        # flag and unit request depends on it (a run under way drains a clock later; START's refusal of a
        # write that also sets ABORT, and the idle engine's answer, read the pulse itself)
        m.d.sync += run.abort.eq(self.abort)
        if self.control_copies:
            run.abort_guard, run.abort_passes = (
                kept_register(m, self.abort, name=f"abort_{group}", platform=platform, reset=True)
                for group in ("guard", "passes"))
        # MODE's decodes as flip-flops (MODE stands still during a run, and the phase machine first reads
        # them after the first pass; START's check reads the code): a flag's or a request's next-state
        # logic then reads one bit, not the code
        m.d.sync += [run.momentum.eq(mode_steps(self.mode, Step.MOMENTUM)),
                     run.fixed_step.eq(mode_steps(self.mode, Step.FIXED))]
        if self.capacity.guard:
            m.d.sync += run.guarded.eq(mode_guarded(self.mode))
        m.d.comb += self.guarded.eq(run.guarded)
        # CYCLES and ITERATIONS have no domain reset: START and the reset's echo clear them (a LUT of the
        # domain's reset and START driving their reset pins is a long path on the board)
        iterations = Signal.like(self.iterations, reset_less=True, name="iterations_q")
        m.d.comb += self.iterations.eq(iterations)
        cleared = self.starting | reset_echo(m, "results_echo")
        self._cycles(m, cleared)
        self._units(m, units, run, platform)
        decisions, stepgen_idle = self._decisions(m, units, run)
        m.d.sync += [self.area_clear.eq(0), self.node_restart.eq(0), self.triangle_restart.eq(0)]
        # The drain's end in two registered stages, so that no unit's request is routed across the
        # device into a wide AND: first each unit's idle state in a register of its own, which the
        # placer puts by the unit (as the sequencer and the guard register theirs), then `drained`
        # from those and the drain flag of this clock and the last. Every first-stage register tells
        # of the clock before, so `drained` also asks that the engine was draining then: nothing
        # starts while draining, so all idle in a draining clock stays all idle, and the drain ends
        # exactly one clock after it would with the AND in one stage.
        units_idle = Signal(len(units) + 1, name="units_idle")
        m.d.sync += units_idle.eq(Cat(*(~run.requests[name] & ~u.i.valid & u.i.ready for name, u in units.items()),
                                      stepgen_idle))
        was_draining = Signal(name="was_draining")
        drained = Signal(name="drained")
        m.d.sync += [was_draining.eq(self.in_drain),
                     drained.eq(self.in_drain & was_draining & self.passes_idle & units_idle.all())]
        self._phases(m, units, run, decisions, drained)
        self._momentum(m, units, run, iterations, cleared)
        return m

    def _fixed_half_dt_sq(self, m: Module, platform) -> Signal:
        """The fixed step's ½Δt² (steplut.half_dt_sq), five stages from the DT register: the product's
        operands, the product, its copy, rounding, saturation; DT is loaded long before a step uses it.
        The product is in a DSP block with its own operand and product registers (``hdl.dsp``)."""
        fs = self.fs
        fixed_sq = Signal(2 * fs.dt.width, reset_less=True, name="fixed_sq")
        fixed_rounded = Signal(2 * fs.dt.width, reset_less=True, name="fixed_rounded")
        fixed_half = Signal(shape_of(fs.half_dt_sq), reset_less=True, name="fixed_half")
        m.d.sync += [fixed_sq.eq(registered_product(m, self.dt, self.dt, name="fixed_dt_sq", platform=platform)),
                     fixed_rounded.eq(shift_round(fixed_sq, 2 * fs.dt.frac_bits + 1 - fs.half_dt_sq.frac_bits,
                                                  fs.rounding)),
                     fixed_half.eq(clamp(fixed_rounded, fs.half_dt_sq)[0])]
        return fixed_half

    def _cycles(self, m: Module, cleared) -> None:
        """CYCLES in two halves, the high half a clock behind the low half's wrap (registered because a
        64-bit carry chain in one clock is among the longest paths); exact a clock after the run.
        Without the domain's reset: ``cleared`` (START accepted, or the reset's echo) clears it."""
        cycles = Signal.like(self.cycles, reset_less=True, name="cycles_q")
        m.d.comb += self.cycles.eq(cycles)
        half = len(cycles) // 2
        cycles_wrapped = Signal(name="cycles_wrapped", reset_less=True)
        m.d.sync += cycles_wrapped.eq(self.running & (cycles[:half] == (1 << half) - 1))
        with m.If(self.running):
            m.d.sync += cycles[:half].eq(cycles[:half] + 1)
        with m.If(cycles_wrapped):
            m.d.sync += cycles[half:].eq(cycles[half:] + 1)
        with m.If(cleared):
            m.d.sync += [cycles.eq(0), cycles_wrapped.eq(0)]

    def _units(self, m: Module, units, run: _Run, platform) -> None:
        """The units' requests and results. A request's valid is set a clock after the phase machine's
        request pulse and held until taken; the payloads are the sums and registers themselves, which
        hold still from the end of their pass until the unit's result is in (the next pass starts after
        the math phase)."""
        fs = self.fs
        norm_length, norm_area, energy = units["norm_length"], units["norm_area"], units["energy_check"]
        beta, stepgen, decision = units["beta"], units["stepgen"], units["decision"]
        length_total = Mux(self.length_sum > fs.error_acc.raw_max, fs.error_acc.raw_max, self.length_sum)
        m.d.comb += [
            energy.half_spring.eq(self.half_spring_held), energy.tolerance.eq(self.tol_energy_held),
            *(u.o.ready.eq(1) for u in units.values()),
            norm_length.i.payload.sum.eq(length_total),
            norm_length.i.payload.mantissa.eq(self.length_reciprocal_held),
            norm_length.i.payload.shift.eq(self.length_shift_held),
            energy.i.payload.square_sum.eq(self.square_sum), energy.i.payload.barrier_sum.eq(self.barrier_sum),
            energy.i.payload.first.eq(run.first_measure),
            norm_area.i.payload.sum.eq(self.area_total),
            norm_area.i.payload.mantissa.eq(self.area_reciprocal_held),
            norm_area.i.payload.shift.eq(self.area_shift_held),
            stepgen.i.payload.area_error.eq(self.area_error), stepgen.i.payload.shape_error.eq(self.shape_error),
            decision.i.payload.energy.eq(self.energy), decision.i.payload.first.eq(run.first_measure),
            decision.i.payload.with_momentum.eq(self.step_dt != 0),
            decision.tolerance.eq(self.tol_energy_held), decision.floor.eq(self.energy_floor),
            *([decision.coarse_active.eq(self.coarse), self.coarse_step.eq(decision.coarse_step),
               decision.i.payload.clipped.eq(self.coarse_clipped)] if self.coarse_built else []),
            self.scale_shift.eq(decision.shift),
            self.shape_error_events.eq(norm_length.o.valid & norm_length.o.payload.saturations),
            self.area_error_events.eq(norm_area.o.valid & norm_area.o.payload.saturations),
        ]
        # the step generator's events registered beside it, so that its output valid bit is not routed across
        # the die into the tally's first stage through their gating. They land in the step-wait phase, a
        # clock later, long before the next check phase reads SATURATIONS.
        m.d.sync += self.step_events.eq(Mux(stepgen.o.valid, stepgen.o.payload.saturations, 0))
        # Each unit's input valid beside the unit, set from the phase machine's request pulse and cleared
        # by ABORT from a copy of its own (``kept_register``): no phase flag or ABORT reaches it through the
        # phase machine's logic (the units sit across the device from it). A request lands a clock after
        # its phase move, an ABORT's clear a clock after the drain begins: the drain waits for a request
        # in flight (``units_idle``), as for a unit that took its request in the ABORT's clock.
        for name, unit in units.items():
            request, abort = run.requests[name], kept_register(m, run.abort, name=f"{name}_abort", platform=platform)
            m.d.sync += request.eq(0)
            with m.If(request):
                m.d.sync += unit.i.valid.eq(1)
            with m.If(unit.i.valid & unit.i.ready):
                m.d.sync += unit.i.valid.eq(0)
            with m.If(abort):
                m.d.sync += unit.i.valid.eq(0)
        with m.If(norm_length.o.valid):
            m.d.sync += [self.shape_error.eq(norm_length.o.payload.error), run.math_pending[0].eq(0)]
        with m.If(norm_area.o.valid):
            m.d.sync += [self.area_error.eq(norm_area.o.payload.error), run.math_pending[1].eq(0)]
        with m.If(energy.o.valid):
            m.d.sync += [self.energy.eq(energy.o.payload.energy), run.math_pending[2].eq(0)]
            with m.If(~run.guarded):
                m.d.sync += run.settled.eq(energy.o.payload.settled)
        with m.If(decision.o.valid):  # the guarded step's stop rule is the window's
            m.d.sync += [run.settled.eq(decision.o.payload.settled), run.stalled.eq(decision.o.payload.stalled)]
        with m.If(beta.o.valid):
            m.d.sync += self.step_dt.eq(beta.o.payload)
        with m.If(stepgen.o.valid):
            m.d.sync += [self.step_dt.eq(stepgen.o.payload.dt), self.step_half.eq(stepgen.o.payload.half_dt_sq)]
        # the fixed step is loaded the clock after the step phase (from a flip-flop, as the units'
        # results are), long before the integrate pass's first node reaches the integrator
        m.d.sync += run.fixed_load.eq(0)
        with m.If(run.fixed_load):
            m.d.sync += [self.step_dt.eq(self.dt), self.step_half.eq(run.fixed_half)]

    def _decisions(self, m: Module, units, run: _Run):
        """START's checks and the check phase's decisions, each compare registered the clock before it is
        read (registered because a 32-bit compare into the phase machine's next-state logic is a long
        path). Returns ``({name: flag}, stepgen_idle)``."""
        fs, cap = self.fs, self.capacity
        # START's checks of the run constants, as golden_model's constant_fault states them
        top = 1 << (fs.reciprocal.width - 1)
        reciprocal_bad = [(getattr(self, f"{k}_reciprocal") < top) | (getattr(self, f"{k}_reciprocal") >= 2 * top)
                          | (getattr(self, f"{k}_shift") < fs.error.frac_bits + 2) for k in ("area", "length")]
        faults = [self.vertices > cap.vertices, self.entries > cap.entries, self.triangles > cap.triangles,
                  self.entries == 0, self.triangles == 0, *reciprocal_bad, ~mode_runs(self.mode, guard=cap.guard),
                  mode_steps(self.mode, Step.FIXED) & (self.dt == 0), self.max_iter == 0,
                  *([self.lane_fault] if cap.lanes > 1 else []),
                  *([self.coarse & ~mode_guarded(self.mode)] if self.coarse_built else [])]
        # in two registered stages, each fault and then their OR (MODE's decode and the compares into one
        # flag is five LUTs across the register file): START's pulse comes at least six clocks after a
        # constant's storage changes (its register answers two clocks after the write, the acknowledge
        # is registered, and the next cycle's request and decode take two more)
        constant_faults = Signal(len(faults), name="constant_faults_q")
        m.d.sync += constant_faults.eq(Cat(*faults))
        stepgen = units["stepgen"]
        stepgen_idle = pending_is_zero(m, StepGenerator.latency_of(self.fs), stepgen.i, stepgen.o, name="stepgen_pending")
        names = ("no_mesh_q", "bad_constants_q", "converged_q", "diverged_q", "at_max_iter_q")
        q = {name: Signal(name=name) for name in names}
        limit = self.saturation_limit
        m.d.sync += [q["no_mesh_q"].eq(self.vertices == 0), q["bad_constants_q"].eq(constant_faults.any()),
                     q["converged_q"].eq((self.area_error <= self.tol_area) & (self.shape_error <= self.tol_shape)
                                         & run.settled),
                     q["diverged_q"].eq((limit != 0) & (self.saturations >= limit)),
                     q["at_max_iter_q"].eq(self.iterations == self.max_iter)]
        return q, stepgen_idle

    def _phases(self, m: Module, units, run: _Run, q, drained) -> None:
        """START, ABORT and the phase machine: one block per phase, each enabled by its one-hot flag
        (and the pass-end pulse it waits for), not by a decode of a phase code under ``running``."""
        flags = {name: getattr(self, f"in_{name}") for name in self.phases}

        def move(leaving, entering=None):
            return [flags[leaving].eq(0), *([flags[entering].eq(1)] if entering else [])]

        if self.control_copies:  # running's next value, from the same statements
            m.d.comb += self.running_next.eq(self.running)

        def fetch(**values):
            """The statements that set pass enables (``force=1``: ``fetch_force``), for ``m.d.sync``."""
            return [getattr(self, f"fetch_{name}").eq(value) for name, value in values.items()]

        def set_state(name):
            m.d.sync += [self.state.eq(_code(STATES, name)), self.running.eq(name == "running")]
            if self.control_copies:
                m.d.comb += self.running_next.eq(name == "running")

        def finish(code):  # (no pass is fetching then)
            set_state("done")
            m.d.sync += self.result.eq(_code(RESULTS, code))
            m.d.comb += self.irq_set.eq(1)

        beta, stepgen, decision, requests = units["beta"], units["stepgen"], units["decision"], run.requests
        abort, running = run.abort, self.running
        launch = Signal(name="launch")  # a pulse: START took the run
        m.d.sync += launch.eq(0)
        # ABORT while running drains what is in flight (still "running": START is ignored and the memories
        # answer err until nothing can write them any more), then goes idle with no result. The pass under
        # way fetches to its end (a node half fed to the force pass would never leave it). ABORT while not
        # running goes idle from the pulse itself, and again from its copy: a run that ends in the pulse's
        # clock is then aborted as a run that ended a clock before it would be.
        with m.If(abort & running):
            m.d.sync += [flag.eq(name == "drain") for name, flag in flags.items()]
        with m.If((self.abort | abort) & ~running):
            set_state("idle")
            m.d.sync += self.result.eq(_code(RESULTS, "none"))
        m.d.comb += self.starting.eq(self.start & ~self.abort & ~running)
        with m.If(self.starting):
            m.d.sync += self.result.eq(_code(RESULTS, "none"))
            with m.If(q["no_mesh_q"]):
                finish("no-mesh")
            with m.Elif(q["bad_constants_q"]):
                finish("bad-constants")
            with m.Else():
                set_state("running")
                m.d.sync += [launch.eq(1), run.first_measure.eq(1), run.measuring_again.eq(0)]
        go, go_guard, go_passes = self._go(run)
        # the start phase entered a clock after the run's state, from a register of START's decision: the
        # START write's decode sits by the register bank, the phase flags' logic by the units they drive
        with m.If(go & launch):
            m.d.sync += flags["start"].eq(1)
        with m.If(go & flags["start"]):  # a measurement: the force pass
            m.d.sync += [*fetch(force=1), *move("start", "force")]
        with m.If(go_passes & flags["force"] & self.force_done):
            m.d.sync += [*fetch(force=0, area=1), *move("force", "area"),
                         run.math_pending.eq(0b111), requests["norm_length"].eq(1), requests["energy_check"].eq(1),
                         self.area_clear.eq(1)]
        with m.If(go_passes & flags["area"] & self.area_done):
            m.d.sync += [*fetch(area=0), *move("area", "math"), requests["norm_area"].eq(1)]
        # the last result's clock t clears its math_pending bit (seen at t+1); its event reaches diverged_q
        # at t+5: the check phase starts then, CHECK_SETTLE_CLOCKS after math_pending reads 0
        math_settle = [Signal(name=f"math_settle{k}") for k in range(self.CHECK_SETTLE_CLOCKS)]
        m.d.sync += [math_settle[0].eq(flags["math"] & (run.math_pending == 0)),
                     *(math_settle[k].eq(math_settle[k - 1]) for k in range(1, len(math_settle)))]
        with m.If(go & flags["math"] & math_settle[-1]):
            # the guarded step: each new layout's energy judged (kept or rolled back); the accepted layout
            # measured again after a rollback is not
            with m.If(run.guarded & ~run.measuring_again):
                m.d.sync += [requests["decision"].eq(1), *move("math", "decide")]
            with m.Else():
                m.d.sync += [run.measuring_again.eq(0), *move("math", "check")]
        # the decision's answer registered beside the phase machine, as the step's
        decided, accepted = Signal(name="decided"), Signal(name="decision_accepted")
        m.d.sync += [decided.eq(decision.o.valid), accepted.eq(decision.o.payload.accepted)]
        with m.If(go & flags["decide"] & decided):
            with m.If(accepted):
                m.d.sync += move("decide", "check")
            with m.Else():  # P − V and V = 0, then the accepted layout measured again
                m.d.sync += [*fetch(nodes=1), self.node_restart.eq(1), run.measuring_again.eq(1),
                             *move("decide", "rollback")]
        with m.If(go_guard & flags["rollback"] & self.guard_done):
            m.d.sync += [*fetch(nodes=0), *move("rollback", "start")]
        # as run_image: the saturation limit first, then the stop rule (neither after the first
        # measurement), then the iteration limit
        verdicts = {"diverged": q["diverged_q"] & ~run.first_measure,
                    "stalled": run.guarded & run.stalled & ~run.first_measure,
                    "converged": q["converged_q"] & ~run.first_measure,
                    "max-iterations": q["at_max_iter_q"]}
        checking = go & flags["check"]
        if self.registered_verdict:  # taken from the check phase's first clock, acted on in its second
            verdicts = {code: _registered(m, verdict, f"verdict_{code.replace('-', '_')}")
                        for code, verdict in verdicts.items()}
            checking &= _registered(m, flags["check"], "check_second_clock")
        with m.If(checking):
            m.d.sync += move("check")  # to the step phase, or the run is over
            with m.If(verdicts["diverged"]):
                finish("diverged")
            with m.Elif(verdicts["stalled"]):
                finish("stalled")
            with m.Elif(verdicts["converged"]):
                finish("converged")
            with m.Elif(verdicts["max-iterations"]):
                finish("max-iterations")
            with m.Else():
                m.d.sync += run.first_measure.eq(0)
                if self.coarse_built:  # a step that takes the coarse move: its sums pass and coefficients first
                    with m.If(run.guarded & self.coarse_step):  # (the node counter restarted first: see below)
                        m.d.sync += [self.node_restart.eq(1), *move("check", "coarse")]
                    with m.Else():
                        m.d.sync += move("check", "step")
                else:
                    m.d.sync += move("check", "step")
        if self.coarse_built:
            # the sums pass fetches from the phase's second clock: its first restarts the node counter, which
            # before the run's first integrate pass stands at 0, not at its end as a guard pass finds it
            with m.If(go & flags["coarse"] & ~self.fetch_nodes & ~self.coarse_done):
                m.d.sync += fetch(nodes=1)
            with m.If(go & flags["coarse"] & self.coarse_done):
                m.d.sync += [*fetch(nodes=0), *move("coarse", "step")]
        with m.If(go & flags["step"]):
            with m.If(run.momentum):
                m.d.sync += requests["beta"].eq(1)
            with m.Elif(run.fixed_step):
                m.d.sync += run.fixed_load.eq(1)
            with m.Else():
                m.d.sync += requests["stepgen"].eq(1)
            m.d.sync += move("step", "step_wait")
        # the step is in (``step_dt`` and ``step_half`` loaded) two clocks after a result: a register beside
        # the units gathers their output valid bits, and a copy of it with no logic in front lands beside
        # the phase machine (the units sit across the device; one register with the OR in front is placed
        # by the units, and its route then ends in the phase machine's logic)
        step_result, step_loaded = Signal(name="step_result"), Signal(name="step_loaded")
        m.d.sync += [step_result.eq(beta.o.valid | stepgen.o.valid | run.fixed_load), step_loaded.eq(step_result)]
        with m.If(go & flags["step_wait"] & step_loaded):
            m.d.sync += [*fetch(nodes=1), *move("step_wait", "integrate")]
        with m.If(go & flags["drain"] & drained):
            set_state("idle")
            m.d.sync += move("drain")
            m.d.sync += [self.result.eq(_code(RESULTS, "none")), self.half_rate.eq(0),
                         *fetch(force=0, area=0, nodes=0)]
        with m.If(go_passes & flags["integrate"] & self.integrate_done):
            with m.If(run.guarded):  # the proposals' certificate, then the commit
                m.d.sync += [*fetch(nodes=0, area=1), self.half_rate.eq(1),
                             self.triangle_restart.eq(1), *move("integrate", "stuck")]
            with m.Else():
                m.d.sync += [*fetch(nodes=0), *move("integrate", "start")]
        with m.If(go_guard & flags["stuck"] & self.guard_done):
            m.d.sync += [*fetch(area=0), self.half_rate.eq(0), *fetch(nodes=1), self.node_restart.eq(1),
                         *move("stuck", "hold")]
        with m.If(go_guard & flags["hold"] & self.guard_done):
            m.d.sync += [*fetch(nodes=0, area=1), self.half_rate.eq(1),
                         self.triangle_restart.eq(1), *move("hold", "certify")]
        with m.If(go_guard & flags["certify"] & self.guard_done):
            m.d.sync += [*fetch(area=0), self.half_rate.eq(0), *fetch(nodes=1), self.node_restart.eq(1),
                         *move("certify", "commit")]
        with m.If(go_guard & flags["commit"] & self.guard_done):
            m.d.sync += [*fetch(nodes=0), *move("commit", "start")]

    def _go(self, run: _Run) -> tuple[Value, Value, Value]:
        """No ABORT, for the phase machine's transitions: those that wait on the guard and those that wait
        on a pass's end, with control copies, read ABORT from copies of their own (placed by those
        loads, across the device from the phase machine); the others, and all without the copies,
        from ``run.abort``. Returns ``(others, guard's, passes')``."""
        go = ~run.abort
        return (go, ~run.abort_guard, ~run.abort_passes) if self.control_copies else (go, go, go)

    def _momentum(self, m: Module, units, run: _Run, iterations: Signal, cleared) -> None:
        """``k`` and the restart for β_k, and ITERATIONS, each moved by a registered pulse of its own.

        The divider's ``k`` is loaded on every clock: ``momentum_k`` and ``restart_pending`` stand still
        from the step phase until the divider takes the request, the clock after. ``restart_pending``
        is set from S's sign (a flip-flop) at the integrate pass's end and cleared by a pulse of its
        own (the launch's or the step's), not by the pulses that move ``momentum_k``: registered so
        that no LUT is shared between the 32-bit update and the flag's enable. With ``control_copies`` the
        step's pulse is the β request and the clear the OR of the two pulses (both flip-flops)."""
        beta = units["beta"]
        go, go_guard, go_passes = self._go(run)
        momentum_k = run.momentum_k
        restart_pending, step_was_restart = Signal(name="restart_pending"), Signal(name="step_was_restart")
        m.d.sync += beta.i.payload.eq(Mux(restart_pending, 0, momentum_k))
        launch_pulse, step_pulse, iterate_pulse, restart_pulse, restart_clear, power_negative = (
            Signal(name=n) for n in ("launch_pulse", "step_pulse", "iterate_pulse", "restart_pulse",
                                     "restart_clear", "power_negative"))
        # a rollback restarts the momentum (the rolled-back step's S is void), as a run's start does
        launching = (self.in_start & run.first_measure) | (self.in_rollback & self.guard_done)
        ending = go_passes & self.in_integrate & self.integrate_done
        committed = go_guard & self.in_commit & self.guard_done  # the guarded step's iteration ends with its commit
        if self.control_copies:
            # the step's pulse is the β request itself, loaded from the same condition in the same clock, and
            # the restart's clear the OR of the two pulses: the step phase's logic then has no load but the
            # request, by the phase machine, not one across the device by k
            step_pulse, restart_clear = run.requests["beta"], launch_pulse | run.requests["beta"]
            m.d.sync += launch_pulse.eq(launching)
        else:
            stepping = go & self.in_step & run.momentum
            m.d.sync += [launch_pulse.eq(launching), step_pulse.eq(stepping), restart_clear.eq(launching | stepping)]
        m.d.sync += [iterate_pulse.eq(Mux(run.guarded, committed, ending)),
                     restart_pulse.eq(ending & run.momentum & ~step_was_restart),
                     power_negative.eq(self.power_sum < 0)]
        with m.If(launch_pulse):  # a run's start: no momentum yet
            m.d.sync += momentum_k.eq(0)
        with m.If(step_pulse):
            m.d.sync += [momentum_k.eq(Mux(restart_pending, 1, momentum_k + 1)), step_was_restart.eq(restart_pending)]
        with m.If(restart_clear):
            m.d.sync += restart_pending.eq(0)
        with m.If(restart_pulse):
            m.d.sync += restart_pending.eq(power_negative)
        with m.If(iterate_pulse):
            m.d.sync += iterations.eq(iterations + 1)
        with m.If(cleared):  # (never with iterate_pulse, which comes while running)
            m.d.sync += iterations.eq(0)
