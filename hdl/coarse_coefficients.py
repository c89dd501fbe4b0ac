"""The coarse space's once-per-iteration arithmetic: the coefficients ``c = M·g`` from a pass's sums ``g = ΦᵀF``.

The RTL twin of :func:`golden_model.fixed.coarse.coefficients` and of
:func:`~golden_model.fixed.coarse.move_shift` of :func:`~golden_model.fixed.coarse.move_frac_bits`: the sums to
25-bit mantissas with one exponent, ``M·g`` exact, the result to 18-bit mantissas with one exponent, and the
shift that takes a node's ``Φ_i·c`` to [accel] (:class:`~hdl.coarse_node.CoarseNode`'s ``move_shift``). In the
engine it runs once per iteration that takes the coarse move (:class:`~hdl.coarse_passes.CoarsePasses`).
"""

from __future__ import annotations

from amaranth.hdl import Cat, Const, Module, Mux, Signal, signed
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from golden_model.coarse import COARSE_DEGREE_MAX, basis_exponents
from golden_model.fixed import FormatSet
from golden_model.fixed.coarse import (MATRIX_BITS, MATRIX_EXPONENT_BITS, OPERAND_BITS, SUM_BITS,
                                       mantissa_magnitude_bits, move_frac_base, move_shift_range, sum_bits)

from .coarse_node import move_shift_shape
from .fixedpoint import round_half_bit, variable_shift
from .force_pass import format_set
from .parameters import check_in_range, check_int

__all__ = ["CoarseCoefficients"]


#: Bits a group of the bit length's first step takes (:func:`_group_lengths`).
LENGTH_GROUP = 8
#: A mantissa's shift in two clocks: by the exponent's multiple of ``2^SHIFT_SPLIT_BITS``, then by the rest.
SHIFT_SPLIT_BITS = 3


def _bit_length(value, width: int):
    """The bit length of the unsigned ``value`` (``width`` bits): a priority encoder, as the OR of one term a bit
    (its position where it is the highest set bit), not a chain of multiplexers ``width`` deep."""
    length = Const(0, range(width + 1))
    for bit in range(width):
        highest = value[bit] & ~value[bit + 1:width].any() if bit + 1 < width else value[bit]
        length = length | Mux(highest, bit + 1, 0)
    return length


def _group_lengths(value, width: int) -> list:
    """The bit length's first step: each :data:`LENGTH_GROUP` bits of ``value``'s, from the lowest (0: none set)."""
    return [_bit_length(value[low:min(low + LENGTH_GROUP, width)], min(LENGTH_GROUP, width - low))
            for low in range(0, width, LENGTH_GROUP)]


def _length_of_groups(lengths: list, width: int):
    """The bit length's second step: the highest group with a bit set, its offset plus its own length."""
    total = Const(0, range(width + 1))
    for k, length in enumerate(lengths):
        higher = Cat(*(other != 0 for other in lengths[k + 1:]))
        highest = (length != 0) & ~higher.any() if k + 1 < len(lengths) else length != 0
        total = total | Mux(highest, k * LENGTH_GROUP + length, 0)
    return total


class CoarseCoefficients(wiring.Component):
    """``c`` and the move's shift from the sums of a pass, bit-exact with the golden model::

        e_g = max(0, bitlen(max ‖g‖) − (SUM_BITS − 2));     g' = rq_half_up(g >> e_g)      (2m values)
        a_kd = Σ_j M_kj·g'_jd                                (exact)
        e_c = max(0, bitlen(max ‖a‖) − (OPERAND_BITS − 2));  c = rq_half_up(a >> e_c)
        move_shift = clamp(2·BASIS_FRAC_BITS + F_n + matrix_exponent − e_g − e_c − accel.frac,
                           −accel.width, MOVE_BITS + 1)

    Parameters
    ----------
    fs : :class:`~golden_model.fixed.FormatSet` or preset name
        The force_acc (its narrowed form's fraction bits ``F_n``) and accel formats.
    degree : int
        The coarse space's degree, 1 … :data:`~golden_model.coarse.COARSE_DEGREE_MAX` (``m`` functions).
    max_nodes : int
        The sums' width (:func:`golden_model.fixed.coarse.sum_bits`), as :class:`~hdl.coarse_node.CoarseNode`'s.
    read_latency : int
        Clocks from ``matrix_addr`` to its entry on ``matrix_data`` (1: a block RAM's registered read; the
        engine's memories register the address first, :attr:`~hdl.memory_windows.MemoryWindows.read_latency`).

    Members
    -------
    i : ``In(stream.Signature(StructLayout({"sums": ArrayLayout(vector, m)})))``
        A pass's exact sums ``g`` (:attr:`CoarseNode.sums <hdl.coarse_node.CoarseNode>`).
    o : ``Out(stream.Signature(StructLayout({"coefficients": ArrayLayout(vector of signed 18, m), "move_shift"})))``
        The coefficients' mantissas and the move's shift, held until taken.
    matrix_exponent : ``In(signed(MATRIX_EXPONENT_BITS))``
        ``M``'s exponent (:class:`~golden_model.fixed.coarse.CoarseConstants`); hold it while a result is formed.
    matrix_addr : ``Out(range(m·m))``, matrix_data : ``In(signed(SUM_BITS))``
        A read port on ``M`` (row-major, ``|M_kj| < 2^MATRIX_BITS``): the entry at ``matrix_addr`` is expected on
        ``matrix_data`` ``read_latency`` clocks later; the address holds from then until the entry is taken.

    Contract
    --------
    One item at a time: ``i.ready`` is high while idle, ``o.valid`` and ``o.payload`` are registers. :attr:`cycles`
    clock edges from the input transfer to the output transfer when ``o.ready`` is high: ``2m + 3`` for ``e_g``
    (a value's magnitude ORed in a clock, the bit length in two steps, the exponent), ``2m + 2`` for
    ``g'`` (a value a clock shifted by the exponent's multiple of ``2^SHIFT_SPLIT_BITS``, by the rest a clock later,
    rounded a clock after that), ``m²`` products of ``MATRIX_BITS + 2 + read_latency`` clocks each (the read, the
    entry taken into a register, the operands' load with the entry's sign, and a shift-add step per bit of
    ``|M_kj| < 2^MATRIX_BITS``, both coordinates at once), one for the last row's sums to land, ``2m + 3`` for
    ``e_c``, ``2m + 2`` for ``c``, one for the shift and one for the output transfer (2,793 at degree 3). No
    multiplier blocks: two adders as wide as the products. ``‖v‖`` is the magnitude as the leading sign bits count
    it, as :func:`~golden_model.fixed.coarse.block_mantissas` does: ``v``, or ``~v`` below 0 (an XOR a bit, where
    ``|v|`` would take a carry chain). Each clock's logic is one of: an XOR and an OR, a priority encoder, a
    subtraction, a variable shift, a rounding add, a negation, an add (``benchmarks/synth_coarse_units.py`` places
    the unit alone; ``docs/guard.md`` gives its clock alone and in the engine).
    """

    def __init__(self, fs: FormatSet | str, degree: int, max_nodes: int, *, read_latency: int = 1):
        fs = format_set(fs, "CoarseCoefficients")
        check_in_range("degree", degree, 1, COARSE_DEGREE_MAX)
        check_int("max_nodes", max_nodes)
        check_int("read_latency", read_latency)
        self.fs, self.degree, self.max_nodes, self.read_latency = fs, degree, max_nodes, read_latency
        self.m = m = len(basis_exponents(degree))
        #: Bits of an exact ``a_kd`` (signed): ``|M| < 2^MATRIX_BITS``, ``|g'| ≤ 2^(SUM_BITS − 2)``, m terms.
        self.product_bits = MATRIX_BITS + mantissa_magnitude_bits(SUM_BITS) + (m - 1).bit_length() + 1
        self.cycles = (2 * m + 3) + (2 * m + 2) + m * m * (MATRIX_BITS + 2 + read_latency) + 1 \
            + (2 * m + 3) + (2 * m + 2) + 1 + 1
        vector = lambda bits: data.StructLayout({"x": signed(bits), "y": signed(bits)})  # noqa: E731
        super().__init__({
            "i": In(stream.Signature(data.StructLayout({"sums": data.ArrayLayout(vector(sum_bits(max_nodes)), m)}))),
            "o": Out(stream.Signature(data.StructLayout({"coefficients": data.ArrayLayout(vector(OPERAND_BITS), m),
                                                         "move_shift": move_shift_shape(fs)}))),
            "matrix_exponent": In(signed(MATRIX_EXPONENT_BITS)),
            "matrix_addr": Out(range(m * m)),
            "matrix_data": In(signed(SUM_BITS)),
        })

    def elaborate(self, platform):
        fs, m = self.fs, self.m
        mod = Module()
        count = 2 * m  # a vector's values, (k, x) then (k, y), k = 0 … m − 1
        width = sum_bits(self.max_nodes)
        # register files that rotate instead of being indexed: each sequential step works on element 0
        sums = [Signal(signed(width), name=f"g{j}", reset_less=True) for j in range(count)]
        g = [Signal(signed(SUM_BITS), name=f"g_mantissa{j}", reset_less=True) for j in range(count)]
        a = [Signal(signed(self.product_bits), name=f"a{j}", reset_less=True) for j in range(count)]
        # an exponent in steps: the OR of the magnitudes a value a clock, its bit length in two, the exponent
        magnitude = Signal(max(width, self.product_bits), name="magnitude", reset_less=True)
        length = Signal(range(len(magnitude) + 1), name="length", reset_less=True)
        group_lengths = [Signal(range(LENGTH_GROUP + 1), name=f"group_length{k}", reset_less=True)
                         for k in range(-(-len(magnitude) // LENGTH_GROUP))]
        e_g = Signal(range(width + 1), name="sum_exponent", reset_less=True)
        e_c = Signal(range(self.product_bits + 1), name="c_exponent", reset_less=True)
        # a mantissa in three steps: the shift by the exponent's multiple of 2^SHIFT_SPLIT_BITS, by the rest
        # (``t``, the half-lsb in bit 0), then the rounding add
        partial = Signal(signed(max(width, self.product_bits) + 1), name="partial", reset_less=True)
        shifted = Signal.like(partial, name="shifted", reset_less=True)
        index = Signal(range(count + 3), name="index", reset_less=True)
        row, column = Signal(range(m), name="row", reset_less=True), Signal(range(m), name="column", reset_less=True)
        address = Signal(range(m * m), name="address", reset_less=True)  # row·m + column, counted (no multiplier)
        steps = Signal(range(MATRIX_BITS + 1), name="steps", reset_less=True)
        multiplier = Signal(MATRIX_BITS, name="multiplier", reset_less=True)  # |M_kj|
        entry = Signal(signed(SUM_BITS), name="entry", reset_less=True)  # M_kj, as read
        # ±g_j: the entry's sign taken at the operand, so that a step is one add; −g_j formed while the entry is read
        negated = {d: Signal(signed(SUM_BITS + 1), name=f"negated_{d}", reset_less=True) for d in "xy"}
        multiplicand = {d: Signal(signed(self.product_bits), name=f"multiplicand_{d}", reset_less=True) for d in "xy"}
        accumulator = {d: Signal(signed(self.product_bits), name=f"accumulator_{d}", reset_less=True) for d in "xy"}
        coefficients = [self.o.payload.coefficients[k][d] for k in range(m) for d in "xy"]

        names = ("idle", "sum_magnitude", "sum_groups", "sum_length", "sum_exponent", "sum_mantissas", "read", "take",
                 "load", "step", "last_row", "c_magnitude", "c_groups", "c_length", "c_exponent", "c_mantissas", "shift",
                 "done")
        state = {name: Signal(name=f"in_{name}", init=(name == "idle")) for name in names}

        def goto(current, name):
            """One-hot: ``current``'s flag falls, ``name``'s rises (each flag's next value a few terms, not a
            chain through every state's condition)."""
            return [state[current].eq(0), state[name].eq(1)]

        def rotate(values, new):
            """Each value takes the next one's, the last takes ``new``."""
            return [v.eq(n) for v, n in zip(values, [*values[1:], new])]

        # The register files rotate, and rounded values land, where a flip-flop of their own says so, set and
        # cleared a clock ahead: each enables a thousand bits or so, too many for a net through the index's
        # compares and the state's decode in one clock.
        turning = {"sum": Signal(name="sums_turning"), "c": Signal(name="a_turning")}
        refining = Signal(name="refining")
        exponent_low = Signal(SHIFT_SPLIT_BITS, name="exponent_low", reset_less=True)  # the exponent's rest
        landing = {"sum": Signal(name="g_landing"), "c": Signal(name="c_landing")}

        def exponent_steps(values, prefix, exponent, keep, then):
            """``exponent = max(0, bitlen(OR of |v|) − keep)`` of ``values`` (which rotate back to their order):
            ``count`` clocks of magnitudes ORed in (``turning`` set on entry), two of the bit length, one of the
            exponent."""
            with mod.If(state[f"{prefix}_magnitude"]):
                # the magnitude as the leading sign bits count it (v, or ~v below 0: an XOR a bit, no carry
                # chain), ORed in
                v = values[0]
                ones = v.as_unsigned() ^ v[-1].replicate(len(v))
                mod.d.sync += [magnitude.eq(magnitude | ones), index.eq(index + 1)]
                with mod.If(index == count - 1):
                    mod.d.sync += [turning[prefix].eq(0), *goto(f"{prefix}_magnitude", f"{prefix}_groups")]
            with mod.If(state[f"{prefix}_groups"]):  # the bit length in two steps: each group's, then the highest
                mod.d.sync += [*(q.eq(v) for q, v in zip(group_lengths, _group_lengths(magnitude, len(magnitude)))),
                               *goto(f"{prefix}_groups", f"{prefix}_length")]
            with mod.If(state[f"{prefix}_length"]):
                mod.d.sync += [length.eq(_length_of_groups(group_lengths, len(magnitude))),
                               *goto(f"{prefix}_length", f"{prefix}_exponent")]
            with mod.If(state[f"{prefix}_exponent"]):
                value = Mux(length > keep, length - keep, 0)
                mod.d.sync += [exponent.eq(value), exponent_low.eq(value[:SHIFT_SPLIT_BITS]), index.eq(0),
                               turning[prefix].eq(1), *goto(f"{prefix}_exponent", then)]
            with mod.If(turning[prefix]):
                mod.d.sync += rotate(values, values[0])

        def mantissa_steps(current, prefix, values, exponent, results, bits, then):
            """``results``: each of ``values`` shifted right by ``exponent``, rounded half up (``bits`` of it),
            ``count + 2`` clocks: ``values[0]`` (rotating) shifted by the exponent's multiple of
            ``2^SHIFT_SPLIT_BITS`` into ``partial``, by the rest into ``shifted`` a clock later, and rounded a clock
            after that (``landing``)."""
            with mod.If(turning[prefix]):
                whole = Cat(Const(0, SHIFT_SPLIT_BITS), exponent[SHIFT_SPLIT_BITS:])
                mod.d.sync += partial.eq(variable_shift(values[0], whole, "half_up")[0])
            with mod.If(index == count - 1):
                mod.d.sync += turning[prefix].eq(0)
            with mod.If(index == 0):
                mod.d.sync += refining.eq(1)
            with mod.If(index == count):
                mod.d.sync += refining.eq(0)
            with mod.If(index == 1):
                mod.d.sync += landing[prefix].eq(1)
            mod.d.sync += index.eq(index + 1)
            with mod.If(index == count + 1):
                mod.d.sync += [landing[prefix].eq(0), *goto(current, then)]

        with mod.If(refining):  # (the half-lsb is bit 0 of partial already: the rest shifts t itself)
            mod.d.sync += shifted.eq(partial >> exponent_low)

        def landing_steps(prefix, results, bits):
            with mod.If(landing[prefix]):
                mod.d.sync += rotate(results, round_half_bit(shifted, "half_up")[:bits].as_signed())

        mod.d.comb += [self.i.ready.eq(state["idle"]), self.matrix_addr.eq(address)]
        with mod.If(state["idle"] & self.i.valid):
            mod.d.sync += [v.eq(self.i.payload.sums[k][d]) for v, (k, d) in zip(sums, ((k, d) for k in range(m)
                                                                                       for d in "xy"))]
            mod.d.sync += [magnitude.eq(0), index.eq(0), turning["sum"].eq(1), *goto("idle", "sum_magnitude")]
        exponent_steps(sums, "sum", e_g, mantissa_magnitude_bits(SUM_BITS), "sum_mantissas")
        with mod.If(state["sum_mantissas"]):  # g' of the sums, shifted into g
            mantissa_steps("sum_mantissas", "sum", sums, e_g, g, SUM_BITS, "read")
            with mod.If(index == count + 1):
                mod.d.sync += [row.eq(0), column.eq(0), address.eq(0), *(accumulator[d].eq(0) for d in "xy")]
        waited = Signal(range(self.read_latency), name="read_waited", reset_less=True)
        with mod.If(state["read"]):  # matrix_addr is presented; its entry arrives read_latency clocks later
            mod.d.sync += [negated["x"].eq(-g[0]), negated["y"].eq(-g[1])]
            if self.read_latency == 1:
                mod.d.sync += goto("read", "take")
            else:
                mod.d.sync += waited.eq(waited + 1)
                with mod.If(waited == self.read_latency - 1):
                    mod.d.sync += [waited.eq(0), *goto("read", "take")]
        with mod.If(state["idle"]):
            mod.d.sync += waited.eq(0)
        with mod.If(state["take"]):  # the entry into a register of its own, off the memory's output
            mod.d.sync += [entry.eq(self.matrix_data), *goto("take", "load")]
        with mod.If(state["load"]):  # g[0], g[1]: column j's x and y (g rotates by two a product)
            negative = entry < 0
            mod.d.sync += [multiplier.eq(Mux(negative, -entry, entry)),
                           multiplicand["x"].eq(Mux(negative, negated["x"], g[0])),
                           multiplicand["y"].eq(Mux(negative, negated["y"], g[1])),
                           *(v.eq(n) for v, n in zip(g, [*g[2:], g[0], g[1]])),
                           steps.eq(MATRIX_BITS), *goto("load", "step")]
        with mod.If(state["step"]):
            for d in "xy":
                with mod.If(multiplier[0]):
                    mod.d.sync += accumulator[d].eq(accumulator[d] + multiplicand[d])
                mod.d.sync += multiplicand[d].eq(multiplicand[d] << 1)
            mod.d.sync += [multiplier.eq(multiplier >> 1), steps.eq(steps - 1)]
            with mod.If(steps == 1):
                with mod.If(column == m - 1):
                    # the row's last product: its sums are complete a clock later, when the next read starts
                    mod.d.sync += column.eq(0)
                    with mod.If(row == m - 1):
                        mod.d.sync += goto("step", "last_row")
                    with mod.Else():
                        mod.d.sync += [row.eq(row + 1), address.eq(address + 1), *goto("step", "read")]
                with mod.Else():
                    mod.d.sync += [column.eq(column + 1), address.eq(address + 1), *goto("step", "read")]
        row_done = Signal(name="row_done")
        mod.d.sync += row_done.eq(state["step"] & (steps == 1) & (column == m - 1))
        with mod.If(row_done):  # the row's two sums, complete now, shifted into a; the accumulators start again
            mod.d.sync += [*(v.eq(n) for v, n in zip(a, [*a[2:], accumulator["x"], accumulator["y"]])),
                           accumulator["x"].eq(0), accumulator["y"].eq(0)]
        with mod.If(state["last_row"]):  # the last row's sums land in a at this clock's end
            mod.d.sync += [magnitude.eq(0), index.eq(0), turning["c"].eq(1), *goto("last_row", "c_magnitude")]
        exponent_steps(a, "c", e_c, mantissa_magnitude_bits(OPERAND_BITS), "c_mantissas")
        with mod.If(state["c_mantissas"]):  # c of a, shifted into the output
            mantissa_steps("c_mantissas", "c", a, e_c, coefficients, OPERAND_BITS, "shift")
        landing_steps("sum", g, SUM_BITS)
        landing_steps("c", coefficients, OPERAND_BITS)
        with mod.If(state["shift"]):
            shift = move_frac_base(fs) - fs.accel.frac_bits + self.matrix_exponent - e_g - e_c
            low, high = move_shift_range(fs)
            mod.d.sync += [self.o.payload.move_shift.eq(Mux(shift < low, low, Mux(shift > high, high, shift))),
                           self.o.valid.eq(1), *goto("shift", "done")]
        with mod.If(state["done"] & self.o.ready):
            mod.d.sync += [self.o.valid.eq(0), *goto("done", "idle")]
        return mod
