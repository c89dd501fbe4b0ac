# amaranth: UnusedElaboratable=no
"""Stage-by-stage pipeline construction shared by every datapath block.

A :class:`Pipeline` hands out the registers of a pipeline written one stage after the
other inside one :class:`~amaranth.hdl.Module`: :meth:`Pipeline.stage` starts a stage
(and registers the valid bit), :meth:`Pipeline.reg` registers a value in it,
:meth:`Pipeline.mul` starts a product as 18×18 partial products (one DSP block each,
operands and product registered: the product is there two stages later) and
:meth:`Pipeline.reduce` adds partial products pairwise, one adder level per stage.
Data registers have no reset (only the valid bits do), so the reset does not fan out
across the datapath either.

Two kinds of pipeline:

* **stalling** (``advance`` given): every register loads only while ``advance`` is high.
  The blocks that are streams of their own (:class:`~hdl.rsqrt.RsqrtUnit`,
  :class:`~hdl.stepgen.StepGenerator`) use ``advance = ~o.valid | o.ready``. Inside a
  larger design whose ``o.ready`` is tied high, ``advance`` is constant and the enables
  vanish in synthesis.
* **free-running** (``advance=None``): every register loads on every clock; nothing
  fans out to the registers but the clock. :class:`~hdl.node_update.NodeUpdate` runs
  this way and turns back-pressure into credits at its input.

A block's latency is counted, not computed: it builds its datapath once into a throwaway
module (:func:`count_stages`) and reads :attr:`Pipeline.stages` of the pipelines it built.
:class:`LiveValues` carries a datapath's values from stage to stage.

(The first line of this file silences Amaranth's unused-elaboratable warning for the modules
created here: :func:`count_stages`'s module is never elaborated, by design.)
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

from amaranth.hdl import Cat, Const, Module, Signal, Value
from amaranth.lib.memory import Memory

from .dsp import dsp_target, registered_product
from .fixedpoint import dsp_operands

__all__ = ["LiveValues", "Pipeline", "aligned_add", "count_stages", "join_parts", "reduce_levels"]

T = TypeVar("T")


def aligned_add(a, a_shift: int, b, b_shift: int):
    """``(a << a_shift) + (b << b_shift)`` as ``(value, shift)`` with ``shift = min(a_shift, b_shift)``.

    The bits of the lower-aligned operand below the other one's lsb pass through unchanged
    (``x == ((x >> k) << k) + x[:k]`` holds for signed ``x`` too), so the carry chain is
    only as long as the overlapping part.
    """
    a, b = Value.cast(a), Value.cast(b)
    if a_shift > b_shift:
        a, a_shift, b, b_shift = b, b_shift, a, a_shift
    k = b_shift - a_shift
    if k == 0:
        return a + b, a_shift
    high = a.shift_right(k) + b
    value = Cat(a[:k], high)
    return (value.as_signed() if high.shape().signed else value), a_shift


def reduce_levels(*operand_shapes) -> int:
    """Adder levels :meth:`Pipeline.reduce` needs for the widest of these products (shape pairs)."""
    levels = 0
    for a, b in operand_shapes:
        n = len(dsp_operands(Signal(a), Signal(b)))
        levels = max(levels, (n - 1).bit_length())
    return levels


def join_parts(parts):
    """The value ``sum(p << shift)`` of a one-element partial-product list, or of several (one add)."""
    value, shift = parts[0]
    for p, s in parts[1:]:
        value, shift = aligned_add(value, shift, p, s)
    value = Value.cast(value)
    return value.shift_left(shift)


class Pipeline:
    """Registers of one pipeline, stage by stage.

    A whole multiply (:meth:`multiply`) takes :attr:`MUL_STAGES` stages plus its adder levels
    (:func:`reduce_levels`); the blocks' latency formulas count with both.

    Parameters
    ----------
    m : Module
        Where the registers go (``m.d.sync``).
    valid : Value
        The valid bit entering the first stage.
    advance : Value or None
        Clock enable of every register (a stalling pipeline), or ``None`` (free-running).
    land_operands : bool
        Give every multiply a stage more (:meth:`multiply`): its operands are copied into fabric
        registers before the DSP blocks' input registers, so the route from where an operand is
        computed (a rounding or a saturation) to the DSP blocks it fans out to is a stage's only work.
    platform
        The elaboration platform; :data:`hdl.dsp.ECP5` makes the multipliers ``MULT18X18D``
        instances with their own registers (:func:`hdl.dsp.registered_product`).
    delay_lines : bool
        Let :class:`LiveValues` carry a value that rides along unchanged for :attr:`LUT_DELAY_MIN`
        stages or more in a delay line of distributed RAM (:meth:`delayed`) instead of a register per
        stage. The values each stage presents are the same, clock for clock, valid or not; only the
        flip-flops go (a value carried through a 30-stage datapath is 30 registers, a delay line is a
        few LUT RAM cells and one register).
    """

    #: Stages of a multiply before its adder levels: operands, products (both in the DSP
    #: block), the products landed in fabric registers (one more with ``land_operands``).
    MUL_STAGES = 3
    #: The shortest delay :meth:`delayed` puts in distributed RAM: a ``TRELLIS_DPR16X4`` holds four
    #: bits 16 deep and takes three slices' LUTs, against half a slice per bit and clock of registers.
    LUT_DELAY_MIN = 4

    @classmethod
    def mul_stages(cls, land_operands: bool = False) -> int:
        """Stages of a multiply before its adder levels."""
        return cls.MUL_STAGES + int(land_operands)

    def __init__(self, m: Module, valid, *, advance=None, land_operands: bool = False, platform=None,
                 delay_lines: bool = False):
        self._m = m
        self._advance = advance
        self.land_operands = land_operands
        self._platform = platform
        self.delay_lines = bool(delay_lines)
        self.valid = valid
        self.stages = 0

    def _load(self, signal, value):
        if self._advance is None:
            self._m.d.sync += signal.eq(value)
        else:
            with self._m.If(self._advance):
                self._m.d.sync += signal.eq(value)

    def stage(self, name: str, valid=None):
        """Start the next stage; returns its (registered) valid bit.

        ``valid`` (default: the previous stage's valid bit) is what the new valid bit registers:
        a stage that closes a group of beats (a node's accumulators) passes on only the last one.
        """
        registered = Signal(name=f"{name}_valid")
        self._load(registered, self.valid if valid is None else valid)
        valid = registered
        self.valid = valid
        self.stages += 1
        return valid

    def reg(self, value, shape, name: str):
        """``value`` registered in the current stage, as a signal of ``shape``."""
        sig = Signal(shape, name=name, reset_less=True)
        self._load(sig, value)
        return sig

    def keep(self, value, name: str):
        """``value`` registered with its own shape (a carried value)."""
        return self.reg(value, value.shape(), name)

    def delayed(self, value, clocks: int, name: str) -> Value:
        """``value`` as it was ``clocks`` loads of this pipeline ago: ``clocks`` registers in a row,
        or from :attr:`LUT_DELAY_MIN` clocks on a delay line (``name`` names its parts).

        The delay line is a memory of at least ``clocks − 1`` words read asynchronously, two pointers
        that step with every load, ``clocks − 1`` words apart, and one output register: each load writes
        ``value`` at the write pointer and registers the word at the read pointer, written ``clocks − 1``
        loads before, so the output is exactly the last of ``clocks`` registers in a row (no reset: data
        registers have none either; the words read before the first writes are the memory's zeros, as
        the row's registers start at zero). The read address is a register, so the read path is a
        flip-flop, the RAM's read and the output register. On ECP5 the memory is distributed RAM
        (``ram_style``), whose read is a LUT's delay.
        """
        value = Value.cast(value)
        if clocks < self.LUT_DELAY_MIN or not len(value):
            for i in range(clocks):
                value = self.keep(value, f"{name}_d{i + 1}")
            return value
        depth = 1 << (clocks - 2).bit_length()  # a power of two of at least clocks − 1 words
        attrs = {"ram_style": "distributed"} if dsp_target(self._platform) == "ecp5" else {}
        storage = Memory(shape=value.shape(), depth=depth, init=[], attrs=attrs)
        self._m.submodules[f"{name}_delay_line"] = storage
        write, read = storage.write_port(), storage.read_port(domain="comb")
        write_at = Signal(range(depth), name=f"{name}_delay_write", reset_less=True)
        read_at = Signal(range(depth), init=(1 - clocks) % depth, name=f"{name}_delay_read", reset_less=True)
        self._m.d.comb += [write.addr.eq(write_at), write.data.eq(value), read.addr.eq(read_at),
                           write.en.eq(1 if self._advance is None else self._advance)]
        self._load(write_at, write_at + 1)
        self._load(read_at, read_at + 1)
        return self.reg(read.data, value.shape(), f"{name}_delayed")

    def mul(self, a, b, name: str):
        """``a * b`` as 18×18 partial products ``[(product, shift)]``, one DSP block each.

        Called in stage k with operands valid in stage k − 1: the operands are registered in
        stage k and the products in stage k + 1, so the products are read after the next
        :meth:`stage` call.
        """
        return [(registered_product(self._m, pa, pb, name=f"{name}_pp{i}", enable=self._advance,
                                    platform=self._platform), shift)
                for i, (pa, pb, shift) in enumerate(dsp_operands(a, b))]

    def reduce(self, parts, name: str):
        """One adder level: neighbouring partial products added pairwise, each sum registered.

        ``[(value, shift)]`` in, about half as many out; the sum of ``value << shift`` is exact.
        """
        out = []
        for i in range(0, len(parts), 2):
            pair = parts[i:i + 2]
            value, shift = pair[0] if len(pair) == 1 else aligned_add(*pair[0], *pair[1])
            out.append((self.keep(Value.cast(value), f"{name}_r{i // 2}"), shift))
        return out

    def multiply(self, products: dict, name: str, carry=lambda stage_name: None) -> dict:
        """Whole products ``{key: (a, b)}`` → ``{key: a * b}``, valid after the stages this adds.

        :attr:`MUL_STAGES` stages (``{name}_in``, ``{name}``, ``{name}_out``: operands and
        products registered in the DSP blocks, then the products landed in fabric registers,
        so the route out of the DSP row is all that stage does), then the pairwise adder levels
        ``{name}_sum1``…. With ``land_operands`` a stage ``{name}_land`` comes first: each
        distinct operand copied into a fabric register, so the route into the DSP row is all
        that stage does. ``carry(stage_name)`` is called once in every stage, after it starts,
        to register the caller's other values.
        """
        if self.land_operands:
            self.stage(f"{name}_land")
            landed = {}  # one register per distinct operand (Yosys would merge copies anyway)
            for key, (a, b) in products.items():
                for n, operand in (("a", a), ("b", b)):
                    if id(operand) not in landed:
                        landed[id(operand)] = self.keep(Value.cast(operand), f"{name}_land_{key}_{n}")
            products = {key: (landed[id(a)], landed[id(b)]) for key, (a, b) in products.items()}
            carry(f"{name}_land")
        parts = {key: self.mul(a, b, f"{name}_{key}") for key, (a, b) in products.items()}
        for suffix in ("_in", ""):
            self.stage(f"{name}{suffix}")
            carry(f"{name}{suffix}")
        self.stage(f"{name}_out")
        parts = {key: [(self.keep(Value.cast(v), f"{name}_out_{key}{i}"), shift) for i, (v, shift) in enumerate(p)]
                 for key, p in parts.items()}
        carry(f"{name}_out")
        level = 0
        while any(len(p) > 1 for p in parts.values()):
            level += 1
            self.stage(f"{name}_sum{level}")
            parts = {key: self.reduce(p, f"{name}_sum{level}_{key}") for key, p in parts.items()}
            carry(f"{name}_sum{level}")
        # Each product as wide as ``a * b`` itself: the partial products' sums grow a bit per adder and
        # per alignment shift (72 bits for a 44-bit product), and whatever reads a product (a rounding's
        # carry chain, a saturation's range test) would otherwise span those copies of its sign.
        return {key: _exact_width(join_parts(p), Value.cast(a) * Value.cast(b))
                for (key, p), (a, b) in zip(parts.items(), products.values())}


def _exact_width(value, exact) -> Value:
    """``value`` (equal to ``exact`` for every input) cut to ``exact``'s shape, which holds it."""
    shape = exact.shape()
    value = Value.cast(value)
    if len(value) <= shape.width:
        return value
    cut = value[:shape.width]
    return cut.as_signed() if shape.signed else cut


class _Held:
    """A carried value as ``pipe``'s ``carry``-th carry registered it, not registered since
    (:class:`LiveValues` on a pipeline with ``delay_lines``)."""

    __slots__ = ("value", "pipe", "carry")

    def __init__(self, value: Value, pipe: Pipeline, carry: int):
        self.value, self.pipe, self.carry = value, pipe, carry


class LiveValues(dict):
    """The values a datapath carries from stage to stage, by name (``{name: value}``).

    :meth:`step` starts a stage of a :class:`Pipeline` and registers in it the new values and
    every carried value not dropped, so a value written once rides along until it is dropped;
    :meth:`multiply` does the same through every stage of :meth:`Pipeline.multiply`. A value
    assigned directly (``live[key] = expression``) is registered by the next stage.

    On a pipeline with ``delay_lines`` a carried value is not registered again in each stage: it is
    held as registered where it was last new or last read, and reading it (``live[key]``) delays it
    by the carries since (:meth:`Pipeline.delayed`), as does a stage of another pipeline carrying
    it: what the register built by the last carry would hold. A value dropped unread costs nothing
    past its last read. (Only ``[]``, :meth:`get` and :meth:`pop` read; the other dict views show
    the held values as they are.)
    """

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._last_carry: dict[Pipeline, tuple[int, str]] = {}  # per pipeline: its carries, the last one's name

    def _at_last_carry(self, key: str, held: _Held) -> Value:
        """``held`` as the register of its pipeline's last carry would hold it."""
        carries, name = self._last_carry[held.pipe]
        return held.pipe.delayed(held.value, carries - held.carry, f"{name}_{key}")

    def carry(self, pipe: Pipeline, name: str, drop=(), **new):
        """Register, in ``pipe``'s current stage, ``new`` and every carried value not in ``drop``
        (with ``delay_lines``: hold them, see above)."""
        kept = {}
        for key, value in dict.items(self):
            if key in drop or key in new:
                continue
            if isinstance(value, _Held) and value.pipe is pipe:
                kept[key] = value  # rides along in its delay
                continue
            if isinstance(value, _Held):  # leaving its pipeline: as that pipeline's last carry holds it
                value = self._at_last_carry(key, value)
            kept[key] = pipe.keep(Value.cast(value), f"{name}_{key}")
        for key, value in new.items():
            kept[key] = pipe.keep(Value.cast(value), f"{name}_{key}")
        if pipe.delay_lines:
            carries = self._last_carry.get(pipe, (0, ""))[0] + 1
            kept = {key: value if isinstance(value, _Held) else _Held(value, pipe, carries)
                    for key, value in kept.items()}
            self._last_carry[pipe] = (carries, name)
        self.clear()
        self.update(kept)

    def __getitem__(self, key: str):
        value = super().__getitem__(key)
        if not isinstance(value, _Held):
            return value
        now = self._at_last_carry(key, value)
        super().__setitem__(key, _Held(now, value.pipe, self._last_carry[value.pipe][0]))  # later reads delay from here
        return now

    def get(self, key: str, default=None):
        return self[key] if key in self else default

    def pop(self, key: str, *default):
        value = super().pop(key, *default)
        return self._at_last_carry(key, value) if isinstance(value, _Held) else value

    def step(self, pipe: Pipeline, name: str, drop=(), **new):
        """One stage of ``pipe`` named ``name`` (see :meth:`carry`)."""
        pipe.stage(name)
        self.carry(pipe, name, drop, **new)

    def multiply(self, pipe: Pipeline, name: str, drop=(), later=(), **products):
        """Whole products ``key=(a, b)`` (:meth:`Pipeline.multiply`), each then a carried value;
        the carried values not in ``drop`` ride along (dropped in the multiply's first stage).

        ``later``: functions of these live values, each returning new values (``{name: value}``)
        that the multiply's second, third, … stage registers (a function may also drop
        values it has used: ``live.pop(name)``): work of its own alongside the multiply, in stages
        the multiply takes anyway.
        """
        drops, news = [drop], list(later)
        first = [True]

        def carry(stage_name):
            new = {} if first[0] or not news else news.pop(0)(self)
            first[0] = False
            self.carry(pipe, stage_name, drops.pop() if drops else (), **new)

        self.update(pipe.multiply(products, name, carry))
        assert not news, f"{name}: {len(news)} of later's stages past the multiply's last"


class EventCount:
    """A saturation-event count carried along a datapath in :class:`LiveValues` (as ``"ev"``).

    Each saturation stage registers its overflow flags as ``"ev_pending"`` (:meth:`__call__`),
    and the next saturation stage adds them to the count: a clamp's flag reaches a register
    straight from its comparison, never through the count's adder in the same clock (that
    compare-then-add was the engine's critical path). :meth:`flush` adds the pending flags
    for good. Flags given under a ``gates`` name count only while that gate is high; the groups
    one stage gives are exclusive (at most one of their gates high), so a stage counts at most its
    plain flags plus its widest group (:attr:`counted`, checked against the golden model's
    event tables).
    """

    def __init__(self, live: LiveValues, width: int, **gates):
        self.live, self.width, self.gates = live, width, {k: Value.cast(v) for k, v in gates.items()}
        self.counted: list[int] = []  # per saturation stage: how many events it can count
        self._pending_gates: list = []  # per bit of live["ev_pending"]: its gate, or None

    def _count(self, flags=(), gated=None):
        """The carried count plus the pending flags plus ``flags``/``gated`` (an expression)."""
        terms = []
        if self._pending_gates:
            bits = self.live["ev_pending"]
            terms += [bits[i] if gate is None else bits[i] & gate for i, gate in enumerate(self._pending_gates)]
        terms += [Value.cast(f) for f in flags]
        terms += [Value.cast(f) & self.gates[name] for name, group in (gated or {}).items() for f in group]
        total = sum(terms, self.live["ev"] if "ev" in self.live else Const(0, 1))
        return Value.cast(total)[:self.width]

    def _note(self, flags, gated):
        unknown = set(gated) - set(self.gates)
        assert not unknown, f"no gate for {sorted(unknown)}"
        self.counted.append(len(flags) + max((len(group) for group in gated.values()), default=0))

    def __call__(self, *flags, **gated) -> dict:
        """The values a stage registers for its saturation ``flags`` (and ``gated`` ones, by gate
        name): the count with the previous stage's flags added, and these flags, pending."""
        self._note(flags, gated)
        new = {"ev": self._count()} if self._pending_gates or "ev" in self.live else {}
        bits = list(flags) + [f for group in gated.values() for f in group]
        self._pending_gates = [None] * len(flags) + [self.gates[n] for n, group in gated.items() for _ in group]
        new["ev_pending"] = Cat(*bits)
        return new

    def flush(self, *flags, **gated) -> dict:
        """The values the count's last stage registers: every pending flag and ``flags`` added
        (where a stage of its own would lengthen the block, the last flags are added in theirs)."""
        self._note(flags, gated)
        total = self._count(flags, gated)
        if "ev_pending" in self.live:  # dropped, not read
            del self.live["ev_pending"]
        self._pending_gates = []
        return {"ev": total}


def count_stages(build: Callable[[Module], T]) -> T:
    """``build(m)`` run on a throwaway module, never elaborated; returns what ``build`` returns.

    A block describes its datapath once, in a function of the module it builds into; this runs
    that function for its :attr:`Pipeline.stages` counts, so a latency is the number of stages
    the block really builds, not a formula kept in step with it. ``build`` must create no
    elaboratable of its own (give it stand-in interfaces for its submodules' ports).
    """
    return build(Module())
