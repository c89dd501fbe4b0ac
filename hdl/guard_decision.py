"""The step guard's decision after a guarded step's measurement: keep the step or roll it back, the step
scale, and the windowed stop rule's energy test.

The RTL twin of what :meth:`golden_model.fixed.controller.Controller._advance_guarded` and
:meth:`~golden_model.fixed.controller.Controller.run` decide from the exact energies, with
:class:`golden_model.guard.StepScale`, :class:`golden_model.guard.EnergyWindow` and the energy part of
:meth:`golden_model.fixed.engine.StopRule.converged`. The engine's guarded mode is to run it once per
iteration, after the energy check (``docs/engine-guard.md``); every constant comes from
:mod:`golden_model.guard` and the widths from the energy check's.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Module, Mux, Signal, unsigned
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from golden_model.coarse import JACOBI_STEPS_AFTER_REJECTION
from golden_model.engine_spec.image import ENERGY_TOL_INT_BITS
from golden_model.fixed.engine import ENERGY_TOL_FRAC_BITS
from golden_model.guard import ENERGY_WINDOW, SCALE_GROW_AFTER, SCALE_MAX_SHIFT

from .controller_units import shift_add_step
from .dsp import kept_register
from .layouts import decision_input_layout, decision_output_layout
from .parameters import check_int

__all__ = ["SPLIT_RISE_PARTS", "GuardDecision"]

#: The rise's parts in the engine's builds with a registered verdict (above ``DEFAULT_CAPACITY``): a
#: quarter of the energy's width is a carry chain of about nine ECP5 cells (``docs/synthesis.md``).
SPLIT_RISE_PARTS = 4


class GuardDecision(wiring.Component):
    """A guarded step kept or rolled back, the step scale and the window's energy test, bit-exact with the
    golden model::

        accepted = E ≤ E_kept                          E_kept: the last kept layout's energy
        E_kept   = E if accepted                       (a rolled-back step repeats E_kept)
        scale    = accepted: the accepted count + 1; at SCALE_GROW_AFTER the shift − 1 (not below 0)
                   rolled back: the count 0; the shift + 1 unless the step carried momentum
        stalled  = shift > SCALE_MAX_SHIFT
        window   ← (E_kept, accepted): the last ENERGY_WINDOW + 1 energies, the last ENERGY_WINDOW flags
        settled  = full and a step taken in it, and
                   (E_old == 0 ? E_kept == 0 : |E_kept − E_old| << 40 ≤ ε·E_old, or E_kept < floor)

    With ``coarse``, the coarse space's schedule too (:class:`golden_model.coarse.CoarseSchedule`)::

        coarse_step = coarse_active and left == 0      the next step takes the coarse move
        left        = first: 0;  accepted: left − 1 (not below 0)
                      accepted, a step that took the coarse move and was clipped (the input's clipped):
                      JACOBI_STEPS_AFTER_REJECTION
                      rolled back, a plain gradient step that took the coarse move: JACOBI_STEPS_AFTER_REJECTION,
                      and the scale (shift and count) stays

    The run's first measurement (``first``) restarts everything: the window holds only its energy. A
    decision with ``stalled`` ends the run as ``stalled`` whatever ``settled`` says (the golden model
    stops before the window's test); the shift then stays at ``SCALE_MAX_SHIFT + 1``.

    Parameters
    ----------
    energy_bits : int
        Width of the exact energy (:attr:`hdl.controller_units.EnergyCheck.energy_bits`).
    window : int
        The window's length in iterations (:data:`golden_model.guard.ENERGY_WINDOW`, the guarded mode's
        default; a run constant in the golden model, which the engine's host is to check against it).
    rise_parts : int
        1: the rise ``E > E_kept`` compared in one clock. More: the energies cut into ``rise_parts``
        parts of (nearly) equal width, each part's greater and equal registered, and the rise joined
        from them a clock later (a clock more per decision; the carry chains are a part's width).
    coarse : bool
        Build the coarse space's schedule (``coarse_active``, ``coarse_step``).

    Members
    -------
    i : ``In(stream.Signature(decision_input_layout(energy_bits, coarse)))``
    o : ``Out(stream.Signature(decision_output_layout(energy_bits)))``
    tolerance : ``In(unsigned(ENERGY_TOL_INT_BITS + ENERGY_TOL_FRAC_BITS))``
        ``ε`` raw (``StopRule.energy``), as :class:`~hdl.controller_units.EnergyCheck` takes it.
    floor : ``In(unsigned(energy_bits))``
        ``StopRule.floor`` (``energy_floor_raw``). Both sampled when an item is accepted.
    shift : ``Out(range(SCALE_MAX_SHIFT + 2))``
        The step scale's shift now (a register; the proposal pass reads it).
    coarse_active : ``In(1)``
        With ``coarse`` only: the run has a coarse space (a run constant, steady while a run is under way).
    coarse_step : ``Out(1)``
        With ``coarse`` only: the coming step takes the coarse move (``coarse_active`` and a register); it
        changes with the scale, and the step it is for is the one decided next.

    Contract
    --------
    One item at a time: ``i.ready`` is high while idle. The decision, the window and the scale are
    updated two clocks after the transfer (the rise compared first; three with ``rise_parts`` > 1);
    ``ε·E_old`` then takes ``energy_bits`` clocks (an LSB-first shift-add, with ``|E_kept − E_old|``
    alongside), the compare's halves one more, and
    ``o`` is a register: with ``o.ready`` high the output transfers :attr:`latency`
    (``energy_bits + 5``, one more with ``rise_parts`` > 1) clock edges after the input.
    """

    def __init__(self, energy_bits: int, *, window: int = ENERGY_WINDOW, rise_parts: int = 1, coarse: bool = False):
        check_int("energy_bits", energy_bits, 2)
        check_int("window", window)
        check_int("rise_parts", rise_parts)
        if rise_parts > energy_bits:
            raise ValueError(f"rise_parts ({rise_parts}) must not exceed energy_bits ({energy_bits})")
        if not isinstance(coarse, bool):
            raise TypeError(f"GuardDecision coarse must be a bool, not {coarse!r}")
        self.energy_bits, self.window, self.rise_parts, self.coarse = energy_bits, window, rise_parts, coarse
        self.tolerance_bits = ENERGY_TOL_INT_BITS + ENERGY_TOL_FRAC_BITS
        self.latency = energy_bits + 5 + (rise_parts > 1)
        super().__init__({
            "i": In(stream.Signature(decision_input_layout(energy_bits, coarse))),
            "o": Out(stream.Signature(decision_output_layout(energy_bits))),
            "tolerance": In(unsigned(self.tolerance_bits)),
            "floor": In(unsigned(energy_bits)),
            "shift": Out(range(SCALE_MAX_SHIFT + 2)),
            **({"coarse_active": In(1), "coarse_step": Out(1)} if coarse else {}),
        })

    def elaborate(self, platform):
        m = Module()
        bits, size = self.energy_bits, self.window
        beat = self.i.payload
        kept = Signal(bits, reset_less=True, name="kept")  # the kept layout's energy
        energies = [Signal(bits, reset_less=True, name=f"window{k}") for k in range(size + 1)]  # newest first
        held = Signal(range(size + 2), name="held")  # energies in the window
        taken = Signal(size, name="taken")  # the last `size` flags, newest in bit 0
        accepted_count = Signal(range(SCALE_GROW_AFTER + 1), name="accepted_count")
        shift = self.shift
        tolerance = Signal(self.tolerance_bits, reset_less=True)
        floor = Signal(bits, reset_less=True)
        allowed = Signal(self.tolerance_bits + bits + 1, reset_less=True)  # ε·E_old
        difference = Signal(bits + 1, reset_less=True)  # E_kept − E_old, two's complement
        change = Signal(bits, reset_less=True)
        steps = Signal(range(bits + 1), reset_less=True)
        accepted = Signal(name="accepted")
        idle, rising, deciding, multiplying, halves, comparing = (
            Signal(name=n, init=int(n == "idle"))
            for n in ("idle", "rising", "deciding", "multiplying", "halves", "comparing"))
        energy, first, with_momentum = (Signal.like(v, name=n, reset_less=True) for n, v in
                                        (("energy", beat.energy), ("first", beat.first),
                                         ("with_momentum", beat.with_momentum)))
        m.d.comb += self.i.ready.eq(idle)
        with m.If(self.i.valid & idle):
            m.d.sync += [idle.eq(0), rising.eq(1), energy.eq(beat.energy), first.eq(beat.first),
                         with_momentum.eq(beat.with_momentum), tolerance.eq(self.tolerance), floor.eq(self.floor)]

        # the energy's compare in a clock of its own (a carry chain as wide as the energy, feeding the
        # window's and the scale's enables in the same clock, is too long a path for the engine's clock;
        # with `rise_parts`, in parts over two clocks: the whole chain is too long for it at 3072 vertices),
        # then the decision, the scale and the window in one clock; the scale's next states (grown, shrunk) are
        # formed beside the compare, from registers, so that only the choice between them follows its flag
        rises = Signal(name="rises")
        grows = Signal(name="scale_grows", reset_less=True)
        shift_grown, shift_shrunk = (Signal.like(shift, name=n, reset_less=True)
                                     for n in ("shift_grown", "shift_shrunk"))
        count_grown = Signal.like(accepted_count, name="count_grown", reset_less=True)
        grows_now = accepted_count + 1 >= SCALE_GROW_AFTER
        compared, rise = self._rise(m, rising, energy, kept)
        with m.If(compared):
            m.d.sync += [compared.eq(0), deciding.eq(1), rises.eq(rise), grows.eq(grows_now),
                         shift_grown.eq(Mux(shift > 0, shift - 1, 0)),
                         count_grown.eq(Mux(grows_now, Mux(shift > 0, 0, SCALE_GROW_AFTER), accepted_count + 1)),
                         shift_shrunk.eq(Mux(with_momentum | (shift > SCALE_MAX_SHIFT), shift, shift + 1))]
        newest = Mux(first | ~rises, energy, kept)
        # `deciding` is `compared` a clock later; the window's energies and the kept energy with the scale
        # each move on a copy of their own, placed by them (one flip-flop enabling them all and starting the
        # multiply is a net across the device)
        deciding_window = kept_register(m, compared, name="deciding_window", platform=platform)
        deciding_scale = kept_register(m, compared, name="deciding_scale", platform=platform)
        with m.If(deciding):  # the multiplier, the window's oldest once the new energy is in, in the low bits
            m.d.sync += [deciding.eq(0), multiplying.eq(1), steps.eq(bits), allowed.eq(energies[size - 1])]
        with m.If(deciding_window):
            m.d.sync += [energies[0].eq(newest), *(energies[k].eq(energies[k - 1]) for k in range(1, size + 1))]
            with m.If(first):
                m.d.sync += [held.eq(1), taken.eq(0)]
            with m.Else():
                m.d.sync += [held.eq(Mux(held == size + 1, held, held + 1)), taken.eq(Cat(~rises, taken[:-1]))]
        handover = None
        if self.coarse:
            clipped = Signal(name="coarse_clipped_held", reset_less=True)
            with m.If(self.i.valid & idle):
                m.d.sync += clipped.eq(beat.clipped)
            handover = self._schedule(m, deciding_scale, first, rises, with_momentum, clipped)
        with m.If(deciding_scale):
            m.d.sync += [kept.eq(newest), accepted.eq(first | ~rises)]
            with m.If(first):
                m.d.sync += [shift.eq(0), accepted_count.eq(0)]
            with m.Else():
                with m.If(~rises):
                    m.d.sync += accepted_count.eq(count_grown)
                    with m.If(grows):
                        m.d.sync += shift.eq(shift_grown)
                with m.Else() if handover is None else m.Elif(~handover):
                    # (the shift stops one past SCALE_MAX_SHIFT: the run ends stalled there)
                    m.d.sync += [accepted_count.eq(0), shift.eq(shift_shrunk)]

        # ε·E_old and |E_kept − E_old|, then the compare's halves, then their combination
        oldest = energies[size]
        with m.If(multiplying):
            m.d.sync += [allowed.eq(shift_add_step(allowed, tolerance, bits)), steps.eq(steps - 1),
                         difference.eq(kept - oldest), change.eq(Mux(difference[-1], -difference, difference))]
            with m.If(steps == 1):
                m.d.sync += [multiplying.eq(0), halves.eq(1)]
        limit = allowed[ENERGY_TOL_FRAC_BITS:]
        half = bits // 2
        low_within, high_below, high_equal, kept_zero, oldest_zero = (
            Signal(name=n, reset_less=True) for n in ("low_within", "high_below", "high_equal", "kept_zero",
                                                      "oldest_zero"))
        floor_low, floor_high, floor_equal = (Signal(name=n, reset_less=True)
                                              for n in ("floor_low_below", "floor_high_below", "floor_high_equal"))
        m.d.sync += [low_within.eq(change[:half] <= limit[:half]), high_below.eq(change[half:] < limit[half:]),
                     high_equal.eq(change[half:] == limit[half:]),
                     floor_low.eq(kept[:half] < floor[:half]), floor_high.eq(kept[half:] < floor[half:]),
                     floor_equal.eq(kept[half:] == floor[half:]),
                     kept_zero.eq(kept == 0), oldest_zero.eq(oldest == 0)]
        within = high_below | (high_equal & low_within)
        below_floor = floor_high | (floor_equal & floor_low)  # kept < floor, its halves compared apart
        ready = (held == size + 1) & taken.any()
        change_ok = Mux(oldest_zero, kept_zero, within)
        with m.If(halves):
            m.d.sync += [halves.eq(0), comparing.eq(1)]
        with m.If(comparing):
            out = self.o.payload
            m.d.sync += [comparing.eq(0), self.o.valid.eq(1), out.accepted.eq(accepted), out.energy.eq(kept),
                         out.settled.eq(~first & ready & (change_ok | below_floor)),
                         out.stalled.eq(shift > SCALE_MAX_SHIFT), out.shift.eq(shift)]
        with m.If(self.o.valid & self.o.ready):
            m.d.sync += [self.o.valid.eq(0), idle.eq(1)]
        return m

    def _schedule(self, m: Module, deciding: Signal, first: Signal, rises: Signal, with_momentum: Signal,
                  clipped: Signal):
        """The coarse space's schedule, moved with the scale: the Jacobi steps left and ``coarse_step``. Returns
        the hand-over of this decision (a rolled-back plain gradient step that took the coarse move), which keeps
        the scale; an accepted step that took it, ``clipped``, hands over too, and the scale moves as for any
        accepted step."""
        left = Signal(range(JACOBI_STEPS_AFTER_REJECTION + 1), name="jacobi_left")
        left_zero = Signal(name="jacobi_left_zero", init=1)  # left == 0, a flip-flop of its own
        m.d.comb += self.coarse_step.eq(self.coarse_active & left_zero)
        handover = self.coarse_step & ~with_momentum & rises & ~first
        with m.If(deciding):
            with m.If(first):
                m.d.sync += [left.eq(0), left_zero.eq(1)]
            with m.Elif(~rises & self.coarse_step & clipped):
                m.d.sync += [left.eq(JACOBI_STEPS_AFTER_REJECTION), left_zero.eq(0)]
            with m.Elif(~rises):
                m.d.sync += [left.eq(Mux(left_zero, 0, left - 1)), left_zero.eq(left <= 1)]
            with m.Elif(handover):
                m.d.sync += [left.eq(JACOBI_STEPS_AFTER_REJECTION), left_zero.eq(0)]
        return handover

    def _rise(self, m: Module, rising: Signal, energy: Signal, kept: Signal):
        """The clock flag in which the rise ``energy > kept`` is ready, and the rise: with one part
        ``rising`` and the compare itself; with more, each part's greater and equal registered in
        ``rising`` and the rise joined from them, most significant part first, in ``joining``."""
        if self.rise_parts == 1:
            return rising, energy > kept
        bounds = [self.energy_bits * k // self.rise_parts for k in range(self.rise_parts + 1)]
        parts = [slice(low, high) for low, high in zip(bounds, bounds[1:])]
        greater, equal = (Signal(self.rise_parts, name=n, reset_less=True) for n in ("rise_greater", "rise_equal"))
        joining = Signal(name="joining")
        with m.If(rising):
            m.d.sync += [rising.eq(0), joining.eq(1),
                         greater.eq(Cat(energy[part] > kept[part] for part in parts)),
                         equal.eq(Cat(energy[part] == kept[part] for part in parts))]
        rise = greater[0]
        for k in range(1, self.rise_parts):
            rise = greater[k] | (equal[k] & rise)
        return joining, rise
