"""The engine controller's once-per-iteration arithmetic as small sequential units.

Each unit is bit-exact with the golden-model function it mirrors
(:mod:`golden_model.fixed.engine`):

* :class:`Normaliser`: an error sum times a host reciprocal, rounded into ``[error]``
  (:meth:`Reciprocal.normalise <golden_model.fixed.measures.Reciprocal.normalise>`);
* :class:`EnergyCheck`: the exact energy of a pass (:func:`~golden_model.fixed.measures.energy_raw`)
  and the stopping rule's relative-change test (the energy part of
  :meth:`StopRule.converged <golden_model.fixed.engine.StopRule.converged>`);
* :class:`BetaDivider`: the momentum ``β_k = k/(k+3)`` (:func:`~golden_model.fixed.measures.momentum_beta_raw`).

They run once per iteration, so they trade cycles for area: products are LSB-first shift-add
multiplies (one multiplicand addition per clock, :func:`shift_add_step`), the divider restores
one quotient bit per clock. Each takes one item at a time: ``i.ready`` is high only while the
unit is idle, ``o`` holds its result (a register, independent of ``o.ready``) until taken.
"""

from __future__ import annotations

from amaranth.hdl import Cat, Module, Mux, Signal, Value, signed, unsigned
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from golden_model.fixed import FormatSet
from golden_model.fixed.engine import ENERGY_TOL_FRAC_BITS
from golden_model.fixed.measures import energy_shifts
from golden_model.engine_spec.image import ENERGY_TOL_INT_BITS, energy_check_width

from .dsp import kept_register
from .fixedpoint import FormatSetNotBuildable, clamp, shape_of, shift_round
from .layouts import energy_result_layout, energy_sums_layout, normalise_layout, saturations_shape
from .parameters import check_int

__all__ = ["shift_add_step", "Normaliser", "EnergyCheck", "BetaDivider"]


def shift_add_step(product, multiplicand, multiplier_bits: int) -> Value:
    """One clock of an LSB-first shift-add multiply of unsigned values.

    ``product`` is a register of ``len(multiplicand) + multiplier_bits + 1`` bits, loaded with
    the multiplier in its low ``multiplier_bits`` bits and zeros above; after ``multiplier_bits``
    steps it holds ``multiplicand · multiplier``. Each step adds the multiplicand to the high
    part if the multiplier's current bit (bit 0) is set and shifts the whole register right by
    one: the adder is only as wide as the multiplicand, and the product's low bits move into the
    places the multiplier's used bits leave.
    """
    product, multiplicand = Value.cast(product), Value.cast(multiplicand)
    assert len(product) == len(multiplicand) + multiplier_bits + 1
    high = product[multiplier_bits:] + Mux(product[0], multiplicand, 0)
    return Cat(product[1:multiplier_bits], high)[:len(product)]


def _check_fs(unit: str, fs) -> FormatSet:
    if isinstance(fs, str):
        fs = FormatSet.preset(fs)
    if not isinstance(fs, FormatSet):
        raise TypeError(f"{unit} needs a FormatSet or a preset name, not {fs!r}")
    return fs


class Normaliser(wiring.Component):
    """``sum/total`` raw [error] from a sum [error_acc] and the host's reciprocal of ``total``.

    Bit-exact with :meth:`Reciprocal.normalise <golden_model.fixed.measures.Reciprocal.normalise>`
    (``fmt = fs.error``, ``fs.rounding``)::

        product = sum · mantissa                                   (exact)
        kept    = (product >> (shift − F − 2)) | sticky            (F = error.frac_bits: the
                                                                     half-lsb and one sticky bit kept)
        error   = sat(rq(kept, F + 2 → error))

    Parameters
    ----------
    fs : :class:`~golden_model.fixed.FormatSet` or preset name
    saturations : :class:`bool`
        Also report whether the result saturated (an error of 1 or more: the golden model counts
        it, as ``area_error`` or ``shape_error``).

    Members
    -------
    i : ``In(stream.Signature(normalise_layout(fs)))``
        ``sum`` [error_acc], ``mantissa`` [reciprocal] and ``shift`` of
        :class:`~golden_model.fixed.measures.Reciprocal` (the host's registers). ``shift`` must be
        at least ``F + 2``, as ``normalise`` needs: every ``Reciprocal.of(total)`` is if
        ``reciprocal`` has at least two more fraction bits than ``error`` (7 more in both presets),
        else every one with ``total ≥ 2``.
    o : ``Out(stream.Signature(Normaliser.output_layout(fs, saturations)))``
        The normalised error: ``shape_of(fs.error)``; with ``saturations``, a struct of ``error``
        and ``saturations`` (1 bit: the result saturated).

    Contract
    --------
    One item at a time: ``i.ready`` is high while idle (nothing accepted or the result taken).
    :meth:`cycles` clock edges from the input transfer to the output transfer when ``o.ready``
    is high: ``reciprocal.width`` multiply steps, ``min(shift − F − 2, product bits)`` shift
    steps (a longer shift leaves only the sticky bit, as this many does), one rounding, one
    saturation (two clocks: each is a carry chain as wide as the product), and the output
    transfer. ``o.valid`` and ``o.payload`` are registers.
    """

    def __init__(self, fs: FormatSet | str, *, saturations: bool = False):
        fs = _check_fs("Normaliser", fs)
        if fs.reciprocal.width < 2:
            raise FormatSetNotBuildable(f"Normaliser needs a reciprocal of at least 2 bits (the shift steps are "
                                        f"worked out during the multiply steps), not {fs.reciprocal.width}")
        self.fs = fs
        self.saturations = bool(saturations)
        self.product_bits = fs.error_acc.width + fs.reciprocal.width + 1
        super().__init__({
            "i": In(stream.Signature(normalise_layout(fs))),
            "o": Out(stream.Signature(self.output_layout(fs, self.saturations))),
        })

    @staticmethod
    def output_layout(fs: FormatSet, saturations: bool = False):
        """Payload of ``o``: the error raw [error]; with ``saturations``, ``error`` and ``saturations``."""
        if not saturations:
            return shape_of(fs.error)
        return data.StructLayout({"error": shape_of(fs.error), "saturations": saturations_shape(1)})

    def shift_steps(self, shift: int) -> int:
        """Clocks the unit spends shifting the product right for a reciprocal's ``shift``."""
        return min(max(shift - self.fs.error.frac_bits - 2, 0), self.product_bits)

    def cycles(self, shift: int) -> int:
        """Clock edges from the input transfer to the output transfer, ``o.ready`` high."""
        return self.fs.reciprocal.width + self.shift_steps(shift) + 3

    def elaborate(self, platform):
        fs = self.fs
        m = Module()
        mantissa_bits = fs.reciprocal.width
        multiplicand = Signal(shape_of(fs.error_acc), reset_less=True)
        product = Signal(self.product_bits, reset_less=True)
        sticky = Signal(reset_less=True)
        steps = Signal(range(max(mantissa_bits, self.product_bits) + 1), reset_less=True)
        # The shift steps, min(max(shift − F − 2, 0), product bits), are worked out from a copy of
        # the host's shift during the multiply steps, not when the item is accepted: the subtract
        # and clamp after the engine's run-constant multiplexer did not fit one clock
        shift_held = Signal.like(self.i.payload.shift, name="shift_held", reset_less=True)
        drop = shift_held - (fs.error.frac_bits + 2)
        shift_steps = Mux(drop < 0, 0, Mux(drop > self.product_bits, self.product_bits, drop))
        remaining_shift = Signal.like(steps, name="remaining_shift")
        # kept: the product with its sticky bit ORed into bit 0, then the two kept bits dropped
        kept = Cat(product[0] | sticky, product[1:])
        rounded_value = shift_round(kept, 2, fs.rounding)
        rounded = Signal.like(rounded_value, name="rounded", reset_less=True)
        error, saturated = clamp(rounded, fs.error)

        # The states as one flip-flop each (one-hot): the product register's next value is chosen by
        # a flag, not a decode of a state code (the decode into the 65-bit multiplexer's select was
        # among the engine's longest paths)
        names = ("idle", "multiply", "shift", "round", "saturate", "done")
        state = {name: Signal(name=f"in_{name}", init=(name == "idle")) for name in names}

        def goto(name):
            return [flag.eq(n == name) for n, flag in state.items()]

        m.d.comb += self.i.ready.eq(state["idle"])
        with m.If(state["idle"] & self.i.valid):
            m.d.sync += [multiplicand.eq(self.i.payload.sum), product.eq(self.i.payload.mantissa),
                         sticky.eq(0), steps.eq(mantissa_bits), shift_held.eq(self.i.payload.shift),
                         *goto("multiply")]
        with m.If(state["multiply"]):
            # loaded on every multiply step (the held shift does not change); the first load is
            # read at the last step, which __init__'s two-step minimum makes a later clock
            m.d.sync += [product.eq(shift_add_step(product, multiplicand, mantissa_bits)), steps.eq(steps - 1),
                         remaining_shift.eq(shift_steps)]
            with m.If((steps == 1) & (remaining_shift == 0)):
                m.d.sync += goto("round")
            with m.Elif(steps == 1):
                m.d.sync += goto("shift")
        with m.If(state["shift"]):
            m.d.sync += [product.eq(product >> 1), sticky.eq(sticky | product[0]),
                         remaining_shift.eq(remaining_shift - 1)]
            with m.If(remaining_shift == 1):
                m.d.sync += goto("round")
        with m.If(state["round"]):
            m.d.sync += [rounded.eq(rounded_value), *goto("saturate")]
        with m.If(state["saturate"]):
            if self.saturations:
                m.d.sync += [self.o.payload.error.eq(error), self.o.payload.saturations.eq(saturated)]
            else:
                m.d.sync += self.o.payload.eq(error)
            m.d.sync += [self.o.valid.eq(1), *goto("done")]
        with m.If(state["done"] & self.o.ready):
            m.d.sync += [self.o.valid.eq(0), *goto("idle")]
        return m


class EnergyCheck(wiring.Component):
    """The exact energy of a pass and the stopping rule's relative-change test against the last one.

    Bit-exact with :func:`~golden_model.fixed.measures.energy_raw` and the energy part of
    :meth:`StopRule.converged <golden_model.fixed.engine.StopRule.converged>`::

        E       = (3·½C·Σe²) << s_springs + (2·Σc·h) << s_barrier     (``energy_frac_bits`` fraction bits)
        settled = E == 0                                  if E_prev == 0
                  |E − E_prev| << 40 ≤ ε·E_prev           otherwise (ε at 40 fraction bits)

    ``E_prev`` is the energy of the previous item (a register). The last test is evaluated as
    ``|E − E_prev| ≤ (ε·E_prev) >> 40``, the same for integers, so the comparison is only as
    wide as ``E``.

    Parameters
    ----------
    fs : :class:`~golden_model.fixed.FormatSet` or preset name
    entries_capacity : int
        The most neighbour entries of a pass: the sums' widths (:func:`~hdl.layouts.energy_sums_layout`)
        hold ``capacity·max(e)²`` and ``capacity·max(c)·max(h)``, and ``energy_bits`` holds
        the largest ``E`` of sums of those widths with the largest ``½C``.
    load_copy : bool
        ``ε·E_prev``'s register loaded with ``E_prev`` by a copy of the energy phase's flag of its own
        (a ``kept_register`` loaded as the flag is, so equal to it in every clock), placed by that
        register's shift-add loop rather than by the flag's other loads (the engine's builds above
        ``DEFAULT_CAPACITY``; ``docs/synthesis.md``). No clock changes.

    Members
    -------
    i : ``In(stream.Signature(energy_sums_layout(fs, entries_capacity)))``
        A pass's exact ``square_sum`` Σe² and ``barrier_sum`` Σc·h; ``first`` marks the run's
        first pass (its ``settled`` is 0: nothing to compare with).
    o : ``Out(stream.Signature(energy_result_layout(energy_bits)))``
        ``energy`` (``E``, ``energy_raw``) and ``settled``.
    half_spring : ``In(unsigned(fs.spring.width − 1))``
        ``½C`` raw [spring], non-negative (``C > 0``). Sampled when an item is accepted.
    tolerance : ``In(unsigned(ENERGY_TOL_INT_BITS + ENERGY_TOL_FRAC_BITS))``
        ``ε`` raw (``StopRule.energy``) in the engine's run-constant format, u8.40
        (:mod:`golden_model.engine_spec.image`). Sampled when an item is accepted.

    Contract
    --------
    One item at a time: ``i.ready`` is high while idle. ``latency`` clock edges from the input
    transfer to the output transfer when ``o.ready`` is high: one to load ``Σe²`` into the multiply,
    ``len(square_sum)`` steps of ``Σe²·(3·½C)``, one to copy the product, one for ``E``,
    ``energy_bits`` steps of ``ε·E_prev`` (with ``|E − E_prev|`` alongside), one to copy ``ε·E_prev``
    into a register beside the comparison, two for the comparison, one for the output register and
    the output transfer. ``o.valid`` and ``o.payload`` are
    registers. The adders are as wide as ``3·½C``, ``ε``, and (one clock each) ``E``.
    """

    def __init__(self, fs: FormatSet | str, entries_capacity: int, *, load_copy: bool = False):
        fs = _check_fs("EnergyCheck", fs)
        check_int("entries_capacity", entries_capacity)
        if not isinstance(load_copy, bool):
            raise TypeError(f"load_copy must be a bool, not {load_copy!r}")
        self.fs, self.load_copy = fs, load_copy
        self.entries_capacity = entries_capacity
        sums = energy_sums_layout(fs, entries_capacity)
        self.square_bits = sums["square_sum"].shape.width
        self.barrier_bits = sums["barrier_sum"].shape.width
        self.springs_shift, self.barrier_shift = energy_shifts(fs)
        self.half_spring_bits = fs.spring.width - 1
        self.spring_factor_bits = self.half_spring_bits + 2  # 3·½C
        self.energy_bits = energy_check_width(fs, self.square_bits, self.barrier_bits)
        self.tolerance_bits = ENERGY_TOL_INT_BITS + ENERGY_TOL_FRAC_BITS
        self.latency = self.square_bits + self.energy_bits + 8
        super().__init__({
            "i": In(stream.Signature(sums)),
            "o": Out(stream.Signature(energy_result_layout(self.energy_bits))),
            "half_spring": In(unsigned(self.half_spring_bits)),
            "tolerance": In(unsigned(self.tolerance_bits)),
        })

    def elaborate(self, platform):
        m = Module()
        beat = self.i.payload
        factor = Signal(self.spring_factor_bits, reset_less=True)  # 3·½C
        barrier = Signal(self.barrier_bits, reset_less=True)
        first = Signal(reset_less=True)
        # the shift-add multiply's register reads and feeds only registers of its own (``square`` in,
        # ``product`` out), so that its loop (the register, the adder, the multiplicand) is placed together
        # rather than pulled towards the sums' source and E's adder
        square = Signal(self.square_bits, reset_less=True)
        springs = Signal(self.spring_factor_bits + self.square_bits + 1, reset_less=True)
        product = Signal(self.spring_factor_bits + self.square_bits, reset_less=True)
        energy = Signal(self.energy_bits, reset_less=True)
        previous = Signal(self.energy_bits, reset_less=True)
        tolerance = Signal(self.tolerance_bits, reset_less=True)
        allowed = Signal(self.tolerance_bits + self.energy_bits + 1, reset_less=True)  # ε·E_prev
        difference = Signal(signed(self.energy_bits + 1), reset_less=True)  # E − E_prev
        change = Signal(self.energy_bits, reset_less=True)  # |E − E_prev|, from difference a clock later
        previous_zero = Signal(reset_less=True)
        energy_zero = Signal(reset_less=True)
        steps = Signal(range(max(self.square_bits, self.energy_bits) + 1), reset_less=True)

        total = product.shift_left(self.springs_shift) + \
                barrier.shift_left(1 + self.barrier_shift)
        within = Signal(reset_less=True)  # |E − E_prev| ≤ (ε·E_prev) >> 40, registered: read two clocks after the last step
        settled = Mux(first, 0, Mux(previous_zero, energy_zero, within))

        # Its phases as flip-flops of their own, no state code (as BetaDivider: an FSM's state, which
        # also reaches the engine's phase machine through ``i.ready``, fanned out to every wide register
        # here). ``busy`` chooses every register's input: while it is low they follow the input (the
        # values a start needs), so ``i.ready`` reaches only the phase flip-flops.
        idle = Signal(init=1)
        busy = Signal()
        in_load, in_springs, in_product, in_energy, in_tolerance, in_copy, in_halves, in_within, in_compare = (
            Signal(name=f"in_{n}")
            for n in ("load", "springs", "product", "energy", "tolerance", "copy", "halves", "within", "compare"))
        last = Signal()  # the springs or tolerance phase's last step
        # ``in_springs | in_tolerance``, a flip-flop of its own: the step count's only control besides the
        # start and the energy phase (the phase flags also choose wide registers' inputs, and a LUT
        # shared between the two gets placed far from both)
        counting = Signal()
        start = self.i.valid & idle
        m.d.comb += self.i.ready.eq(idle)
        with m.If(start):
            m.d.sync += [idle.eq(0), busy.eq(1), in_load.eq(1)]
        with m.If(in_load):
            m.d.sync += [in_load.eq(0), in_springs.eq(1), counting.eq(1)]
        m.d.sync += [
            # 3·½C as an adder: ``* 3`` became a combinational DSP block
            factor.eq(Mux(busy, factor, self.half_spring.shift_left(1) + self.half_spring)),
            barrier.eq(Mux(busy, barrier, beat.barrier_sum)),
            first.eq(Mux(busy, first, beat.first)),
            tolerance.eq(Mux(busy, tolerance, self.tolerance)),
            square.eq(Mux(busy, square, beat.square_sum)),
            springs.eq(Mux(in_load, square, Mux(in_springs, shift_add_step(springs, factor, self.square_bits),
                                                springs))),
            product.eq(springs[:len(product)]),
        ]
        with m.If(~busy):  # loaded while idle, as the other registers (not by `start`: a long path)
            m.d.sync += [steps.eq(self.square_bits), last.eq(self.square_bits == 1)]
        with m.If(counting):
            m.d.sync += [steps.eq(steps - 1), last.eq(steps == 2)]
        with m.If(in_springs & last):
            m.d.sync += [in_springs.eq(0), in_product.eq(1), counting.eq(0)]
        with m.If(in_product):  # ``product`` takes the last step's result at this clock's edge
            m.d.sync += [in_product.eq(0), in_energy.eq(1)]
        if self.load_copy:
            # in_energy is in_product a clock later (each a one-clock pulse, both cleared by the reset)
            load_allowed = kept_register(m, in_product, name="load_allowed", platform=platform, reset=True)
            with m.If(in_energy):
                m.d.sync += [energy.eq(total), steps.eq(self.energy_bits), last.eq(self.energy_bits == 1),
                             in_energy.eq(0), in_tolerance.eq(1), counting.eq(1)]
            with m.If(load_allowed):
                m.d.sync += allowed.eq(previous)
        else:
            with m.If(in_energy):
                m.d.sync += [energy.eq(total), allowed.eq(previous), steps.eq(self.energy_bits),
                             last.eq(self.energy_bits == 1), in_energy.eq(0), in_tolerance.eq(1), counting.eq(1)]
        with m.If(in_tolerance):
            # the step count (energy_bits ≥ 2 clocks) leaves time for the difference, then its
            # magnitude: each a carry chain as wide as E, one per clock
            m.d.sync += [allowed.eq(shift_add_step(allowed, tolerance, self.energy_bits)),
                         difference.eq(energy - previous),
                         change.eq(Mux(difference < 0, -difference, difference))]
            with m.If(last):
                m.d.sync += [in_tolerance.eq(0), in_copy.eq(1), counting.eq(0)]
        # ε·E_prev copied, with no logic, into a register beside the comparison: ``allowed`` is placed by
        # its shift-add loop, and the route from there into the compare's carry chain was the long part
        # of the check's worst path
        limit = Signal(len(allowed) - ENERGY_TOL_FRAC_BITS, reset_less=True)
        m.d.sync += limit.eq(allowed[ENERGY_TOL_FRAC_BITS:])
        with m.If(in_copy):
            m.d.sync += [in_copy.eq(0), in_halves.eq(1)]
        # The E-wide comparison in two clocks of its own, free-running: the halves compared, then
        # combined (the whole compare in one clock is a carry chain of over 80 cells behind ε·E_prev)
        half = len(change) // 2
        low_within, high_below, high_equal = (Signal(name=n, reset_less=True)
                                              for n in ("low_within", "high_below", "high_equal"))
        m.d.sync += [low_within.eq(change[:half] <= limit[:half]),
                     high_below.eq(change[half:] < limit[half:]), high_equal.eq(change[half:] == limit[half:]),
                     within.eq(high_below | (high_equal & low_within))]
        with m.If(in_halves):
            m.d.sync += [in_halves.eq(0), in_within.eq(1)]
        with m.If(in_within):
            m.d.sync += [in_within.eq(0), in_compare.eq(1)]
        # E == 0 and E_prev == 0 in two clocks, free-running: 16-bit pieces, then their AND (the whole
        # E-wide zero test in one clock, under in_tolerance's enable, is a deep path). E holds still from the energy phase to the compare, E_prev from one
        # compare to the next, and the tolerance phase takes energy_bits ≥ 2 clocks.
        for value, zero in ((energy, energy_zero), (previous, previous_zero)):
            pieces = [Signal(name=f"{zero.name}_{k}", reset_less=True) for k in range(0, len(value), 16)]
            m.d.sync += [piece.eq(value[16 * k:16 * (k + 1)] == 0) for k, piece in enumerate(pieces)]
            m.d.sync += zero.eq(Cat(*pieces).all())
        with m.If(in_compare):
            m.d.sync += [self.o.payload.energy.eq(energy), self.o.payload.settled.eq(settled),
                         self.o.valid.eq(1), previous.eq(energy), in_compare.eq(0)]
        with m.If(self.o.valid & self.o.ready):
            m.d.sync += [self.o.valid.eq(0), idle.eq(1), busy.eq(0)]
        return m


class BetaDivider(wiring.Component):
    """The momentum factor ``β_k = k/(k+3)`` raw [dt], rounded half up and capped at ``dt.raw_max``.

    Bit-exact with :func:`~golden_model.fixed.measures.momentum_beta_raw`::

        q = (k · 2^(F+1)) // (k + 3)          (F = dt.frac_bits; q < 2^(F+1) since k < k + 3)
        β = min((q + 1) >> 1, dt.raw_max)

    A restoring divider: the remainder starts at ``k`` (the integer part of ``k/(k+3)`` is 0)
    and each clock doubles it, subtracts ``k + 3`` where it fits and shifts the quotient bit in.

    Parameters
    ----------
    fs : :class:`~golden_model.fixed.FormatSet` or preset name
    k_bits : int
        Width of ``k`` (default 21: ``k`` up to ``2**21 − 1``).

    Members
    -------
    i : ``In(stream.Signature(unsigned(k_bits)))``
        The iteration count ``k`` since the last restart.
    o : ``Out(stream.Signature(shape_of(fs.dt)))``
        ``β_k``.

    Contract
    --------
    One item at a time: ``i.ready`` is high while idle. ``latency`` = ``dt.frac_bits + 5`` clock
    edges from the input transfer to the output transfer when ``o.ready`` is high (``F + 1``
    quotient bits, the quotient copied, the rounding, ``o.payload``, the output transfer): 23 for
    both presets. ``o.valid`` and ``o.payload`` are registers. The quotient sits with the
    remainder's logic and ``o.payload`` with β's consumers, across the device from each other in
    the engine: the quotient's copy (no logic) and the rounded β (a carry chain) are two registers
    on that way, so that no route across it ends in the rounding's carry chain.
    """

    def __init__(self, fs: FormatSet | str, k_bits: int = 21):
        fs = _check_fs("BetaDivider", fs)
        check_int("k_bits", k_bits)
        self.fs = fs
        self.k_bits = k_bits
        self.quotient_bits = fs.dt.frac_bits + 1
        self.latency = self.quotient_bits + 4
        super().__init__({
            "i": In(stream.Signature(unsigned(k_bits))),
            "o": Out(stream.Signature(shape_of(fs.dt))),
        })

    def elaborate(self, platform):
        fs = self.fs
        m = Module()
        divisor = Signal(self.k_bits + 1, reset_less=True)  # k + 3
        remainder = Signal(self.k_bits + 1, reset_less=True)  # < divisor
        quotient = Signal(self.quotient_bits, reset_less=True)
        steps = Signal(range(self.quotient_bits + 1), reset_less=True)
        doubled = remainder.shift_left(1)
        fits = doubled >= divisor
        quotient_q = Signal.like(quotient, name="quotient_copy")
        beta, _ = clamp((quotient_q + 1).shift_right(1), fs.dt)

        # Its phases as flip-flops of their own, no state code: an FSM's state register drove both the
        # 50 bits of remainder and quotient and, through ``i.ready``, the engine's phase machine, and
        # ABC shared a LUT between the two, a long route either way. The datapath registers load on
        # every clock, chosen by ``dividing`` alone: while it is low they follow the input (the values
        # a start needs), so ``i.ready``, placed by the engine's control, reaches only ``dividing``
        # and ``idle`` (as the load enable of the remainder's 50 bits it would fan out across the die).
        idle = Signal(init=1)
        dividing = Signal()
        last = Signal()  # the quotient bit being formed is the last one
        copying, rounding, rounded = Signal(), Signal(), Signal()
        beta_q = Signal.like(beta, name="beta_rounded")
        m.d.comb += self.i.ready.eq(idle)
        with m.If(self.i.valid & idle):
            m.d.sync += [idle.eq(0), dividing.eq(1)]
        m.d.sync += [
            divisor.eq(Mux(dividing, divisor, self.i.payload + 3)),
            remainder.eq(Mux(dividing, Mux(fits, doubled - divisor, doubled), self.i.payload)),
            quotient.eq(Mux(dividing, Cat(fits, quotient), 0)),
            steps.eq(Mux(dividing, steps - 1, self.quotient_bits)),
            last.eq(Mux(dividing, steps == 2, self.quotient_bits == 1)),
        ]
        with m.If(dividing & last):
            m.d.sync += [dividing.eq(0), copying.eq(1)]
        m.d.sync += quotient_q.eq(quotient)  # free-running: the quotient is whole in the copying clock only
        with m.If(copying):
            m.d.sync += [rounding.eq(1), copying.eq(0)]
        with m.If(rounding):
            m.d.sync += [beta_q.eq(beta), rounded.eq(1), rounding.eq(0)]
        with m.If(rounded):
            m.d.sync += [self.o.payload.eq(beta_q), self.o.valid.eq(1), rounded.eq(0)]
        with m.If(self.o.valid & self.o.ready):
            m.d.sync += [self.o.valid.eq(0), idle.eq(1)]
        return m
