"""18×18 multipliers with registered operands and product: generic RTL or the ECP5 ``MULT18X18D``.

Every multiply of the datapath is a set of 18×18 partial products
(:func:`~hdl.fixedpoint.dsp_operands`), each computed by :func:`registered_product`:
the operands are registered, then the product — two clocks from operands to product. In
generic RTL (simulation, iCE40, any FPGA tool that infers registered multipliers) that is
two flip-flop levels around a ``*``. Elaborated with :data:`ECP5` as the platform it is one
``MULT18X18D`` whose own input and output registers (``REG_INPUTA/B_CLK``,
``REG_OUTPUT_CLK``) hold them: Yosys's ``synth_ecp5`` maps a ``*`` to a bare
``MULT18X18D`` and leaves the registers in the fabric, where the routing to and from the
DSP row costs 2.5–5.8 ns (``docs/synthesis.md``). Both forms compute the same function
with the same latency; ``tests/sim/test_cocotb.py::test_ecp5_flavour_with_mult18x18d_instances``
simulates the primitive form against the golden model with a model of the primitive
(``sim/models/MULT18X18D.v``).

The platform object also tells :class:`hdl.fifo.LutFIFO` that the device has distributed RAM, and
:func:`kept_register` to make a register copy of ``TRELLIS_FF`` instances that Yosys keeps.
"""

from __future__ import annotations

from amaranth.hdl import ClockSignal, Const, Fragment, Instance, Module, Mux, ResetSignal, Signal, Value, signed, unsigned

from golden_model.fixed.dsp import DSP_WIDTH, is_dsp_block

from .fixedpoint import FormatSetNotBuildable

__all__ = ["ECP5", "DspPlatform", "registered_product", "dsp_target", "kept_register", "ecp5_instance_count",
           "mult18x18d_count"]


class DspPlatform:
    """A minimal Amaranth platform object that only says which multiplier primitive to use."""

    def __init__(self, dsp: str):
        self.dsp = dsp

    def __repr__(self):
        return f"DspPlatform({self.dsp!r})"


#: Elaborate with ``platform=ECP5`` to get ``MULT18X18D`` instances.
ECP5 = DspPlatform("ecp5")


def dsp_target(platform) -> str | None:
    """``"ecp5"`` when ``platform`` asks for ECP5 primitives, else ``None`` (generic RTL)."""
    return getattr(platform, "dsp", None)


def kept_register(m: Module, value, *, name: str, platform=None, reset: bool = False, enable=None) -> Signal:
    """``value`` registered (a flip-flop per bit), kept apart from identical registers.

    A copy of a register placed beside one group of its loads: Yosys merges flip-flops with the same
    input, so with ECP5 primitives each bit is a ``TRELLIS_FF`` instance marked ``keep``; in generic
    RTL (simulation) a plain register. ``reset``: the ECP5 flip-flop is cleared by the ``sync`` domain's
    reset too (its synchronous LSR), as the generic register is, so that a copy of a register loaded
    from the same next value equals it in every clock, a reset's included; without it the ECP5 copy
    ignores the reset (a copy whose loads are all cleared by the reset anyway). ``enable`` (1 bit, or
    ``None``: every clock): the register loads only when it is high, the flip-flop's own clock enable
    (the reset wins over it, as in an Amaranth register).
    """
    value = Value.cast(value)
    q = Signal(len(value), name=name)
    if dsp_target(platform) != "ecp5":
        if enable is None:
            m.d.sync += q.eq(value)
        else:
            with m.If(enable):
                m.d.sync += q.eq(value)
        return q
    # (LSR_OVER_CE, the default SRMODE: a synchronous clear, as the domain's, that wins over the enable)
    clear = {"p_SRMODE": "LSR_OVER_CE", "i_LSR": ResetSignal()} if reset else {"i_LSR": 0}
    load = {"p_CEMUX": "1"} if enable is None else {"p_CEMUX": "CE", "i_CE": enable}
    for i in range(len(value)):
        m.submodules[f"{name}_ff{i}"] = Instance(
            "TRELLIS_FF", p_GSR="AUTO", **load, p_CLKMUX="CLK", p_LSRMUX="LSR", p_REGSET="RESET",
            i_CLK=ClockSignal(), **clear, i_DI=value[i], o_Q=q[i], a_keep=1)
    return q


def registered_product(m: Module, a, b, *, name: str, enable=None, platform=None) -> Value:
    """``a * b`` two clocks later (operands registered, then the product).

    ``a`` and ``b`` fit 18-bit operands (signed if the product is signed: an unsigned operand
    of a signed product is at most 17 bits). ``enable`` is the clock enable of all three
    registers (``None``: always). The returned value has the shape of ``a * b``. With ECP5
    primitives, a product with a 1-bit operand stays in the fabric.
    """
    a, b = Value.cast(a), Value.cast(b)
    shape = (a * b).shape()
    is_signed = shape.signed
    for op in (a, b):
        limit = DSP_WIDTH if (op.shape().signed or not is_signed) else DSP_WIDTH - 1
        if len(op) > limit:
            raise FormatSetNotBuildable(
                f"{name}: a {len(op)}-bit {'signed' if op.shape().signed else 'unsigned'} operand "
                f"does not fit an {DSP_WIDTH}-bit multiplier operand")
    product = Signal(shape, name=name, reset_less=True)
    # A 1-bit operand (the top bit of an unsigned operand in a signed product) makes the
    # product a multiplexer: fabric logic, not a DSP block (the rule the study's cost counts with).
    if dsp_target(platform) == "ecp5" and is_dsp_block(len(a), len(b)):
        operand = signed(DSP_WIDTH) if is_signed else unsigned(DSP_WIDTH)
        a_ext, b_ext = (Signal(operand, name=f"{name}_{n}") for n in "ab")
        p = Signal(2 * DSP_WIDTH, name=f"{name}_p")
        m.d.comb += [a_ext.eq(a), b_ext.eq(b), product.eq(p[:len(product)])]
        ports = {f"i_A{i}": a_ext[i] for i in range(DSP_WIDTH)}
        ports.update({f"i_B{i}": b_ext[i] for i in range(DSP_WIDTH)})
        ports.update({f"i_C{i}": Const(0, 1) for i in range(DSP_WIDTH)})
        ports.update({f"o_P{i}": p[i] for i in range(2 * DSP_WIDTH)})
        m.submodules[name] = Instance(
            "MULT18X18D",
            p_REG_INPUTA_CLK="CLK0", p_REG_INPUTA_CE="CE0", p_REG_INPUTA_RST="RST0",
            p_REG_INPUTB_CLK="CLK0", p_REG_INPUTB_CE="CE0", p_REG_INPUTB_RST="RST0",
            p_REG_INPUTC_CLK="NONE", p_REG_PIPELINE_CLK="NONE",
            p_REG_OUTPUT_CLK="CLK0", p_REG_OUTPUT_CE="CE0", p_REG_OUTPUT_RST="RST0",
            p_GSR="DISABLED", p_RESETMODE="SYNC", p_MULT_BYPASS="DISABLED",
            p_SOURCEB_MODE="B_SHIFT", p_CAS_MATCH_REG="FALSE",
            i_SIGNEDA=Const(int(is_signed), 1), i_SIGNEDB=Const(int(is_signed), 1),
            i_SOURCEA=Const(0, 1), i_SOURCEB=Const(0, 1),
            i_CLK0=ClockSignal(), i_CE0=Const(1, 1) if enable is None else enable, i_RST0=Const(0, 1),
            **ports)
        return product
    a_r = Signal(a.shape(), name=f"{name}_a", reset_less=True)
    b_r = Signal(b.shape(), name=f"{name}_b", reset_less=True)
    if len(b) == 1 and not b.shape().signed:
        value = Mux(b_r, a_r, 0)  # written as a multiplexer, or Yosys may map it to a DSP block
    elif len(a) == 1 and not a.shape().signed:
        value = Mux(a_r, b_r, 0)
    else:
        value = a_r * b_r
    updates = [a_r.eq(a), b_r.eq(b), product.eq(value)]
    if enable is None:
        m.d.sync += updates
    else:
        with m.If(enable):
            m.d.sync += updates
    return product


def ecp5_instance_count(component, cell: str) -> int:
    """Instances of the ECP5 primitive ``cell`` (``"MULT18X18D"``, ``"DP16KD"``) in ``component``
    elaborated with :data:`ECP5`: what ``synth`` maps, counted without running Yosys."""
    count, fragments = 0, [Fragment.get(component, ECP5)]
    while fragments:
        for sub, _, _ in fragments.pop().subfragments:
            if isinstance(sub, Instance):
                count += sub.type == cell
            else:
                fragments.append(sub)
    return count


def mult18x18d_count(component) -> int:
    """``MULT18X18D`` instances in ``component`` elaborated with :data:`ECP5` (what ``synth`` maps)."""
    return ecp5_instance_count(component, "MULT18X18D")
