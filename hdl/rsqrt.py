"""Pipelined reciprocal square root unit: the RTL twin of :mod:`golden_model.fixed.rsqrt`.

Every width, constant and table is taken from a :class:`~golden_model.fixed.RsqrtConfig`;
the unit is bit-exact with :func:`~golden_model.fixed.rsqrt_with_config` for every input.
"""

from amaranth.hdl import *
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

import golden_model.fixed.rsqrt as golden_rsqrt
from golden_model.fixed import FormatSet, Rounding, RsqrtConfig, rsqrt_stages

from .fixedpoint import FormatSetNotBuildable, round_half_bit, saturate, shift_round
from .pipeline import Pipeline, reduce_levels
from .rom import registered_rom

__all__ = ["RsqrtUnit"]


class RsqrtUnit(wiring.Component):
    """Reciprocal square root, fully pipelined, one result per clock.

    Computes ``R = 1/sqrt(X)`` exactly as :func:`golden_model.fixed.rsqrt_with_config` does
    (the same normalisation, seed ROM, Newton steps, roundings and saturation), for every input.
    The roundings are the golden model's internal rsqrt rounding (half up), read from
    :mod:`golden_model.fixed.rsqrt` when the unit is constructed.

    Parameters
    ----------
    config : :class:`~golden_model.fixed.FormatSet` or :class:`~golden_model.fixed.RsqrtConfig`
        A format set (its :meth:`~golden_model.fixed.FormatSet.rsqrt_config` is used:
        ``length_sq`` to ``rsqrt``) or an rsqrt configuration. Input and output formats must be
        unsigned.

    Attributes
    ----------
    config : :class:`~golden_model.fixed.RsqrtConfig`
        The configuration every width and table comes from.
    latency : :class:`int`
        Clock cycles from an input transfer to the output transfer of the same item when
        ``o.ready`` is held high: :meth:`latency_of` (28 for both presets).
        Throughput: one item per clock (II = 1).

    Members
    -------
    i : :py:`In(stream.Signature(unsigned(config.fmt_in.width)))`
        Raw ``X`` in ``config.fmt_in`` (``length_sq``: u7.34 in the default preset).
    o : :py:`Out(stream.Signature(output_layout))`
        :class:`~amaranth.lib.data.StructLayout` payload with fields ``rsqrt`` (raw ``R`` in
        ``config.fmt_out``) and ``saturated`` (1 if the result was clamped to ``raw_max``:
        ``X == 0`` or ``1/sqrt(x)`` above ``fmt_out.max``; the golden model counts exactly these
        events in its :class:`~golden_model.fixed.SaturationCounter`).

    Pipeline (all stages advance together when the output register is empty or being read,
    ``advance = ~o.valid | o.ready``; ``i.ready = advance``):

    ===============  ==========================================================================
    ``norm``         priority encoder on ``X`` (``X = 0`` is treated as ``X = 1``, saturated):
                     left-shift amount, denormalisation shift and its saturation, per bit length
    ``shift``        barrel shifter: mantissa ``M`` (``u2.Fm``), low bits floored
    ``rom``          the seed ROM's block RAM addressed with ``M >> shift`` from the ``M`` register
    ``seed``         seed ROM data registered (on ECP5 in the block RAM's output register)
    ``land``         the seed registered in the fabric, next to the multipliers
    per Newton step  ``y*y`` | round to ``t1`` | ``M*t1`` | round to ``t2`` | ``h = 1 - t2`` |
                     ``y*h`` | round | ``y += ...``: each multiply is DSP partial products
                     (operands and products registered, products landed in fabric registers) and
                     pairwise adder levels
    ``denorm``       barrel shifter ``y >> (s - 1)``
    ``round``        drop the half-lsb bit of ``t`` (``(t + 1) >> 1`` for half up)
    ``o``            saturation, output register
    ===============  ==========================================================================
    """

    def __init__(self, config):
        if isinstance(config, FormatSet):
            config = config.rsqrt_config()
        if not isinstance(config, RsqrtConfig):
            raise TypeError(f"RsqrtUnit needs a FormatSet or an RsqrtConfig, not {config!r}")
        if config.fmt_in.signed:
            raise FormatSetNotBuildable(
                f"RsqrtUnit input format must be unsigned, not {config.fmt_in} "
                f"(the golden model refuses negative inputs)")
        if config.fmt_out.signed:
            raise FormatSetNotBuildable(f"RsqrtUnit output format must be unsigned, not {config.fmt_out}")
        self._config = config
        self._rounding = Rounding(golden_rsqrt.INTERNAL_ROUNDING)
        self.latency = self.latency_of(config)
        super().__init__({
            "i": In(stream.Signature(unsigned(config.fmt_in.width))),
            "o": Out(stream.Signature(self.output_layout(config))),
        })

    @staticmethod
    def latency_of(config):
        """Pipeline latency in clocks for ``config``.

        norm, shift, rom, seed, land; per Newton step 5 stages, 3 multiplies of ``Pipeline.MUL_STAGES`` each plus the adder levels of its three
        multiplies (which depend on the widths); denorm, round, o.
        """
        y, mant = unsigned(config.y_fmt.width), unsigned(config.mant_fmt.width)
        t1, h = unsigned(config.ysq_fmt.width), signed(config.h_fmt.width)
        per_step = 5 + 3 * Pipeline.MUL_STAGES + reduce_levels((y, y)) + reduce_levels((mant, t1)) + reduce_levels((y, h))
        return 8 + per_step * config.newton_steps

    @staticmethod
    def output_layout(config):
        """Payload layout of ``o``: ``rsqrt`` (raw ``config.fmt_out``) and ``saturated``."""
        return data.StructLayout({
            "rsqrt": unsigned(config.fmt_out.width),
            "saturated": unsigned(1),
        })

    @property
    def config(self):
        return self._config

    def _normalisation_table(self):
        """Per bit length ``b`` of ``X``: ``(left shift amount, denorm right shift, saturate)``.

        Obtained by running the golden model on ``X = 2**(b-1)``: the exponent ``e`` and the
        denormalisation shift ``s`` depend on ``b`` only. The mantissa is
        ``M = floor(X * 2**(Fm - e)) = (X << (Fm + R - e)) >> R`` with ``R >= 0`` chosen so
        that every shift amount is a left shift.
        """
        cfg = self._config
        width = cfg.fmt_in.width
        probes = [1 << (b - 1) for b in range(1, width + 1)]
        st = rsqrt_stages(probes, cfg)
        e = [int(v) for v in st["e"]]
        s = [int(v) for v in st["shift"]]
        right = max(0, max(e) - cfg.mant_frac_bits)
        table = {}
        for b, e_b, s_b, m_b in zip(range(1, width + 1), e, s, st["m"]):
            amount = cfg.mant_frac_bits + right - e_b
            assert ((probes[b - 1] << amount) >> right) == int(m_b)
            table[b] = (amount, max(s_b, 1) - 1, s_b <= 0)
        return table, right

    def elaborate(self, platform):
        m = Module()
        cfg = self._config
        rnd = self._rounding
        fy, fm, fw = cfg.y_frac_bits, cfg.mant_frac_bits, cfg.work_frac_bits

        # Global pipeline enable: the whole pipe moves when the output register is empty or
        # being read. valid never depends on ready; a stalled output register holds its payload.
        advance = Signal()
        m.d.comb += [
            advance.eq(~self.o.valid | self.o.ready),
            self.i.ready.eq(advance),
        ]
        pipe = Pipeline(m, self.i.valid, advance=advance, platform=platform)
        stage, reg = pipe.stage, pipe.reg

        # --- norm: priority encoder -> shift amounts (per bit length, from the golden model)
        table, right = self._normalisation_table()
        max_amount = max(a for a, _, _ in table.values())
        max_dn = max(d for _, d, _ in table.values())
        x = self.i.payload
        zero = x == 0
        amount = Signal(range(max_amount + 1))
        dn = Signal(range(max_dn + 1))
        sat_shift = Signal()
        for b, (a_b, dn_b, sat_b) in table.items():  # ascending: the highest set bit wins
            assignments = [amount.eq(a_b), dn.eq(dn_b), sat_shift.eq(sat_b)]
            if b == 1:
                m.d.comb += assignments  # also X = 0, which the golden model computes as X = 1
            else:
                with m.If(x[b - 1]):
                    m.d.comb += assignments
        stage("norm")
        xs = reg(x | zero, unsigned(cfg.fmt_in.width), "norm_x")
        amount_r = reg(amount, amount.shape(), "norm_amount")
        dn_r = reg(dn, dn.shape(), "norm_dn")
        sat_r = reg(zero | sat_shift, 1, "norm_sat")

        # --- shift: mantissa M = floor(X * 2**(Fm - e)) in u2.Fm (barrel shifter), registered
        stage("shift")
        mant_value = ((xs << amount_r) >> right)[:cfg.mant_fmt.width]
        mant = reg(mant_value, cfg.mant_fmt.width, "mant")
        dn_r = reg(dn_r, dn_r.shape(), "shift_dn")
        sat_r = reg(sat_r, 1, "shift_sat")

        # --- rom: the seed ROM's address register, addressed with M >> shift from the mant
        # register;  seed: its data register, in the block RAM itself on ECP5 (hdl/rom.py:
        # the unregistered output, ~5.6 ns, went to a fabric flip-flop). The ROM is indexed by
        # M >> shift itself (no subtraction on the address path): the rows below
        # seed_index_offset are never read and hold 0.
        stage("rom")
        index = mant[cfg.seed_index_shift:]
        assert cfg.seed_index_offset + cfg.seed_table_size <= 1 << len(index)
        seed = registered_rom(m, seed_rom_words(cfg), cfg.seed_frac_bits, index, name="seed_rom", enable=advance,
                              platform=platform)
        mant = reg(mant, mant.shape(), "rom_mant")
        dn_r = reg(dn_r, dn_r.shape(), "rom_dn")
        sat_r = reg(sat_r, 1, "rom_sat")

        stage("seed")
        mant = reg(mant, mant.shape(), "seed_mant")
        dn_r = reg(dn_r, dn_r.shape(), "seed_dn")
        sat_r = reg(sat_r, 1, "seed_sat")

        # --- land: the seed in a fabric register, so that the block RAM's output and the DSP
        # row's inputs are two short routes (one route from the block RAM straight into the
        # multiplier's input register can take most of a clock period)
        stage("land")
        # u0.Fs -> u1.Fy (wiring), as wide as every later y (the multiplies' partial products, latency_of)
        y = reg(seed, cfg.seed_frac_bits, "land_y").shift_left(fy - cfg.seed_frac_bits).as_unsigned()
        y = Cat(y, Const(0, cfg.y_fmt.width - len(y)))
        mant = reg(mant, mant.shape(), "land_mant")
        dn_r = reg(dn_r, dn_r.shape(), "land_dn")
        sat_r = reg(sat_r, 1, "land_sat")

        # --- Newton-Raphson, y <- y + round(y * (1 - round(M * round(y*y))) / 2)
        one_w = 1 << fw
        for n in range(cfg.newton_steps):
            def carry(name, *, with_y=True, with_mant=n + 1 < cfg.newton_steps):
                nonlocal y, mant, dn_r, sat_r
                if with_y:
                    y = reg(y, cfg.y_fmt.width, f"nr{n}_{name}_y")
                if with_mant:  # M is used again by this step, or by the next one
                    mant = reg(mant, mant.shape(), f"nr{n}_{name}_mant")
                dn_r = reg(dn_r, dn_r.shape(), f"nr{n}_{name}_dn")
                sat_r = reg(sat_r, 1, f"nr{n}_{name}_sat")

            # Each multiply is split into 18x18 partial products (one DSP each: operands
            # registered, then products, two stages); adder levels add them pairwise, one
            # adder per stage, then the rounding takes a stage of its own.
            def product(a, b, name, **keep):
                return pipe.multiply({"p": (a, b)}, f"nr{n}_{name}",
                                     lambda stage_name: carry(stage_name.removeprefix(f"nr{n}_"), **keep))["p"]

            y_sq = product(y, y, "ysq", with_mant=True)
            stage(f"nr{n}_t1")
            t1 = reg(shift_round(y_sq, 2 * fy - fw, rnd), cfg.ysq_fmt.width, f"nr{n}_t1")
            carry("t1", with_mant=True)

            m_t1 = product(mant, t1, "mt1")
            stage(f"nr{n}_t2")
            t2 = reg(shift_round(m_t1, fm, rnd), cfg.ysq_fmt.width, f"nr{n}_t2")
            carry("t2")
            stage(f"nr{n}_h")
            h = reg(one_w - t2, signed(cfg.h_fmt.width), f"nr{n}_h")
            carry("h")

            y_h = product(y, h, "yh")
            stage(f"nr{n}_yh_round")
            y_h = reg(shift_round(y_h, fw + 1, rnd), signed(cfg.y_fmt.width + 1), f"nr{n}_yh_round")
            carry("yh_round")
            stage(f"nr{n}_y")
            y = reg(y + y_h, cfg.y_fmt.width, f"nr{n}_y")
            carry("y", with_y=False)

        # --- denorm: t = y >> (s - 1) keeps the half-lsb of R = round(y * 2**-s) as bit 0
        stage("denorm")
        t = y >> dn_r
        y_shifted = reg(t, cfg.y_fmt.width, "denorm_y")
        sticky = Const(0)
        if rnd is Rounding.NEAREST_EVEN:  # a bit below the half-lsb is set
            sticky = reg((t << dn_r) != y, 1, "denorm_sticky")
        sat_r = reg(sat_r, 1, "denorm_sat")

        # --- round: drop the half-lsb bit
        stage("round")
        rounded = reg(round_half_bit(y_shifted, rnd, sticky), cfg.y_fmt.width, "round_r")
        sat_r = reg(sat_r, 1, "round_sat")

        # --- o: saturation, into the output register
        result, overflow = saturate(rounded, cfg.fmt_out)
        saturated = sat_r | overflow
        with m.If(advance):
            m.d.sync += [
                self.o.valid.eq(pipe.valid),
                self.o.payload.rsqrt.eq(Mux(saturated, cfg.fmt_out.raw_max, result)),
                self.o.payload.saturated.eq(saturated),
            ]
        assert pipe.stages + 1 == self.latency, (pipe.stages + 1, self.latency)
        return m


def seed_rom_words(cfg: RsqrtConfig) -> list[int]:
    """The rsqrt unit's seed ROM, word by word: indexed by the mantissa's top bits themselves (no
    subtraction on the address path), so the rows below ``cfg.seed_index_offset`` are never read and hold 0."""
    return [0] * cfg.seed_index_offset + [int(v) for v in cfg.seed_table()]
