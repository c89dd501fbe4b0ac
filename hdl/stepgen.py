"""Pipelined variable step-size generator: the RTL twin of :func:`golden_model.fixed.step_size`.

Every width, constant and table is taken from a :class:`~golden_model.fixed.FormatSet`;
the unit is bit-exact with :func:`~golden_model.fixed.step_size` for every input pair.
"""

from amaranth.hdl import *
from amaranth.lib import data, stream, wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from golden_model.fixed import FormatSet, dt_constant, exp_table, lut_slope_bits, shift_round as gm_shift_round

from .dsp import dsp_target
from .fixedpoint import saturate, shift_round
from .layouts import STEP_EVENTS, saturations_shape
from .pipeline import Pipeline, reduce_levels
from .rom import registered_rom

__all__ = ["StepGenerator", "stepgen_idle_signal", "pending_is_zero"]


class StepGenerator(wiring.Component):
    """Step size ``dt = C + f(E_S) + f(E_C)`` and ``dt**2/2``; fully pipelined, one per clock.

    ``f(E) = 0.1*exp(-5(1-E))`` is read from the golden model's table
    :func:`~golden_model.fixed.exp_table` (``fs.lut_index_bits``, ``fs.lut_entry``), linearly
    interpolated if ``fs.lut_interpolate``; ``C`` is :func:`~golden_model.fixed.dt_constant`.
    Every rounding is ``fs.rounding`` and every overflow saturates, exactly as in
    :func:`golden_model.fixed.step_size` (``area_error`` is its ``E_S``, ``shape_error`` its
    ``E_C``).

    Parameters
    ----------
    fs : :class:`~golden_model.fixed.FormatSet`
        Source of every format, table and knob.
    saturations : :class:`bool`
        Also count each step's saturation events as the golden model's ``SaturationCounter``
        counts them in ``step_size`` (the output field ``saturations``, up to
        :data:`~hdl.layouts.STEP_EVENTS`: ``lut_input`` per lane, ``dt`` twice, ``half_dt_sq``).
        The overflow bits are added into a running count that rides with the step; no stage more.

    Attributes
    ----------
    latency : :class:`int`
        Clock cycles from an input transfer to the output transfer of the same item when
        ``o.ready`` is held high: :meth:`latency_of` (17 for both presets, which interpolate;
        12 without interpolation). Throughput: one item per clock (II = 1).

    Members
    -------
    i : :py:`In(stream.Signature(input_layout))`
        :class:`~amaranth.lib.data.StructLayout` payload: ``area_error``, ``shape_error``
        (raw, ``fs.error``: u0.20 in the default preset).
    o : :py:`Out(stream.Signature(output_layout))`
        :class:`~amaranth.lib.data.StructLayout` payload: ``dt`` (raw ``fs.dt``) and
        ``half_dt_sq`` (raw ``fs.half_dt_sq``); with ``saturations``, ``saturations`` (3 bits).

    Pipeline (all stages advance together when the output register is empty or being read,
    ``advance = ~o.valid | o.ready``; ``i.ready = advance``). The two lookup lanes are identical
    and share one LUT ROM through two asynchronous read ports, each row registered:

    ================  ============================================================================
    ``lut_addr``      the error clamped (``u1.F`` only) and the ROM address registered
    ``lut``           ROM read (asynchronous, registered). Interpolating: address ``k = E >> r``, row
                      ``(T[k], T[k+1] - T[k])``, ``t = E mod 2**r`` registered. Otherwise: row
                      ``T[round(E / 2**r)]``. (A ``u1.F`` error is first clamped to 1.0.)
    ``mul_in``        interpolating only: ``slope``, ``t`` registered in the DSP block
    ``mul``           interpolating only: ``slope * t`` registered in the DSP block
    ``mul_out``       interpolating only: the product landed in fabric registers
    ``mul_sum1``…     interpolating only: adder levels of the partial products (none in the presets)
    ``interp_round``  interpolating only: ``round(slope * t / 2**r)``
    ``interp``        interpolating only: ``v = T[k] + round(slope * t / 2**r)``
    ``sum``           ``v_S + v_C``
    ``dt_round``      requantise to ``fs.dt``
    ``dt_sat``        saturate
    ``dt_add``        ``+ C``
    ``dt``            saturate
    ``sq_in``         ``dt`` registered in the DSP block
    ``sq``            ``dt * dt`` registered in the DSP block
    ``sq_out``        the product landed in fabric registers
    ``sq_sum1``…      adder levels of the partial products (none in the presets)
    ``half``          ``round(dt*dt / 2)`` to ``fs.half_dt_sq``'s lsb
    ``o``             saturate; output register
    ================  ============================================================================
    """

    def __init__(self, fs, *, saturations: bool = False):
        if not isinstance(fs, FormatSet):
            raise TypeError(f"StepGenerator needs a FormatSet, not {fs!r}")
        self._fs = fs
        self.saturations = bool(saturations)
        self.latency = self.latency_of(fs)
        super().__init__({
            "i": In(stream.Signature(self.input_layout(fs))),
            "o": Out(stream.Signature(self.output_layout(fs, self.saturations))),
        })

    @staticmethod
    def input_layout(fs):
        """Payload layout of ``i``: ``area_error``, ``shape_error`` (raw ``fs.error``)."""
        return data.StructLayout({
            "area_error": unsigned(fs.error.width),
            "shape_error": unsigned(fs.error.width),
        })

    @staticmethod
    def output_layout(fs, saturations: bool = False):
        """Payload layout of ``o``: ``dt``, ``half_dt_sq`` (raw ``fs.dt``, ``fs.half_dt_sq``); with
        ``saturations``, the step's event count ``saturations`` (up to :data:`~hdl.layouts.STEP_EVENTS`)."""
        fields = {
            "dt": unsigned(fs.dt.width),
            "half_dt_sq": unsigned(fs.half_dt_sq.width),
        }
        if saturations:
            fields["saturations"] = saturations_shape(sum(STEP_EVENTS.values()))
        return data.StructLayout(fields)

    @staticmethod
    def latency_of(fs):
        """Pipeline latency in clocks for ``fs``.

        lut_addr, lut, sum, dt_round, dt_sat, dt_add, dt, half, o; the ``dt*dt`` multiply
        (``Pipeline.MUL_STAGES`` plus its adder levels); interpolating, the ``slope*t`` multiply
        and interp_round, interp.
        """
        mul = Pipeline.MUL_STAGES
        latency = 9 + mul + reduce_levels((unsigned(fs.dt.width), unsigned(fs.dt.width)))
        if fs.interpolates:
            slope, t = unsigned(lut_slope_bits(fs.lut_index_bits, fs.lut_entry)), unsigned(fs.lut_frac_bits)
            latency += 2 + mul + reduce_levels((slope, t))
        return latency

    @property
    def fs(self):
        return self._fs

    @property
    def _interpolating(self):
        return self._fs.interpolates

    @property
    def _error_max(self):
        return error_max(self._fs)

    def elaborate(self, platform):
        m = Module()
        fs = self._fs
        r = fs.lut_frac_bits

        advance = Signal()
        m.d.comb += [
            advance.eq(~self.o.valid | self.o.ready),
            self.i.ready.eq(advance),
        ]
        pipe = Pipeline(m, self.i.valid, advance=advance, platform=platform)
        reg = pipe.reg

        # Saturation events: a running count that rides with the step, registered in every stage;
        # each saturation adds its overflow bit.
        event_bits = sum(STEP_EVENTS.values()).bit_length()
        events = {"count": None, "counted": 0}

        def stage(name):
            pipe.stage(name)
            if events["count"] is not None:
                events["count"] = reg(events["count"], event_bits, f"{name}_saturations")

        def count(*flags):
            """Add ``flags`` to the count as the current stage registers it (nothing without ``saturations``)."""
            if self.saturations:
                events["counted"] += len(flags)
                total = sum(Value.cast(flag) for flag in flags)
                events["count"] = total if events["count"] is None else events["count"] + total

        # --- lut: the exp table. Generic RTL: one LUT ROM with an asynchronous read port per lane
        # (its address and its row registered). ECP5: a block-RAM ROM per lane (hdl/rom.py: the
        # address registered in the DP16KD, its output register on), because the LUT ROM's
        # multiplexer tree, six LUT levels, was among the engine's longest paths. Same rows, same
        # two stages, so the same function and latency.
        layout, rows = exp_rom_rows(fs)
        block_ram = dsp_target(platform) == "ecp5"
        if not block_ram:
            m.submodules.exp_rom = exp_rom = Memory(shape=layout, depth=len(rows), init=rows,
                                                    attrs={"rom_style": "logic"})
        lanes = ("area_error", "shape_error")
        error, addrs, read_data = {}, {}, {}
        for lane in lanes:
            error[lane] = e = self.i.payload[lane]
            if self._error_max < fs.error.raw_max:  # u1.F: values above 1.0 clamp to 1.0
                above_one = e > self._error_max
                error[lane] = e = Mux(above_one, self._error_max, e)
            else:  # u0.F: there is no more than 1.0 (a compare would be constant: lint's CMPCONST)
                above_one = C(0, 1)
            count(above_one)
            if self._interpolating:
                addr = e >> r
            elif r:
                addr = shift_round(e, r, fs.rounding)
            else:
                addr = e
            addrs[lane] = addr
        # The address is registered before the ROM: the clamp's compare and the ROM's multiplexer
        # tree in one clock were among the engine's longest paths
        stage("lut_addr")
        for lane in lanes:
            if block_ram:
                words = [layout.const(row).as_value().value for row in rows]
                # every reachable address is below len(rows) (as the LUT ROM's port, which truncates)
                read_data[lane] = registered_rom(m, words, layout.size, addrs[lane][:(len(rows) - 1).bit_length()],
                                                 name=f"exp_rom_{lane}", enable=advance, platform=platform)
            else:
                # an asynchronous read port whose data is registered below: the multiply after it
                # starts at a flip-flop
                port = exp_rom.read_port(domain="comb")
                m.d.comb += port.addr.eq(reg(addrs[lane], len(port.addr), f"lut_{lane}_addr"))
                read_data[lane] = port.data
            if self._interpolating:
                error[lane] = reg(error[lane][:r], r, f"lut_addr_{lane}_t")
        stage("lut")
        row = {lane: layout(read_data[lane]) if block_ram else reg(read_data[lane], layout, f"lut_{lane}_row")
               for lane in lanes}
        value = {lane: row[lane].base for lane in lanes}

        if self._interpolating:
            frac = {lane: reg(error[lane], r, f"lut_{lane}_t") for lane in lanes}
            # slope · t in a DSP block: operands registered, then the product (two stages)
            def carry_base(stage_name):
                for lane in lanes:
                    value[lane] = reg(value[lane], fs.lut_entry.width, f"{stage_name}_{lane}_base")
                if events["count"] is not None:
                    events["count"] = reg(events["count"], event_bits, f"{stage_name}_saturations")

            product = pipe.multiply({lane: (row[lane].slope, frac[lane]) for lane in lanes}, "mul", carry_base)
            stage("interp_round")
            for lane in lanes:
                product[lane] = reg(shift_round(product[lane], r, fs.rounding), len(product[lane]) - r + 1,
                                    f"interp_round_{lane}_p")
                value[lane] = reg(value[lane], fs.lut_entry.width, f"interp_round_{lane}_base")
            stage("interp")
            for lane in lanes:
                value[lane] = reg(value[lane] + product[lane], fs.lut_entry.width, f"interp_{lane}_v")

        # --- sum of the two lookups (entry lsb)
        stage("sum")
        v_sum = reg(value["area_error"] + value["shape_error"], fs.lut_entry.width + 1, "v_sum")

        # --- dt = sat(sat(requantize(v_sum)) + C): rounding, saturation, + C, saturation
        stage("dt_round")
        v_rounded = shift_round(v_sum, fs.lut_entry.frac_bits - fs.dt.frac_bits, fs.rounding)
        v_dt = reg(v_rounded, len(v_rounded), "dt_round_v")
        v_dt, dt_over = saturate(v_dt, fs.dt)
        count(dt_over)
        stage("dt_sat")
        v_dt = reg(v_dt, fs.dt.width, "dt_sat_v")
        stage("dt_add")
        v_dt = reg(v_dt + dt_constant(fs.dt), fs.dt.width + 1, "dt_add_v")
        dt, dt_over = saturate(v_dt, fs.dt)
        count(dt_over)
        stage("dt")
        dt = reg(dt, fs.dt.width, "dt")

        # --- dt * dt in a DSP block: operand registered, then the product (two stages)
        def carry_dt(stage_name):
            nonlocal dt
            dt = reg(dt, fs.dt.width, f"{stage_name}_dt")
            if events["count"] is not None:
                events["count"] = reg(events["count"], event_bits, f"{stage_name}_saturations")

        dt_sq = pipe.multiply({"dt_sq": (dt, dt)}, "sq", carry_dt)["dt_sq"]

        # --- half: round(dt*dt / 2) to half_dt_sq's lsb
        stage("half")
        half_rounded = shift_round(dt_sq, 2 * fs.dt.frac_bits + 1 - fs.half_dt_sq.frac_bits, fs.rounding)
        half_rounded = reg(half_rounded, len(half_rounded), "half_r")
        dt = reg(dt, fs.dt.width, "half_dt")

        # --- o: half_dt_sq saturated, into the output register
        half, half_over = saturate(half_rounded, fs.half_dt_sq)
        count(half_over)
        with m.If(advance):
            m.d.sync += [
                self.o.valid.eq(pipe.valid),
                self.o.payload.dt.eq(dt),
                self.o.payload.half_dt_sq.eq(half),
            ]
            if self.saturations:
                assert events["counted"] == sum(STEP_EVENTS.values()), (events["counted"], STEP_EVENTS)
                m.d.sync += self.o.payload.saturations.eq(events["count"])
        assert pipe.stages + 1 == self.latency, (pipe.stages + 1, self.latency)
        return m


def error_max(fs: FormatSet) -> int:
    """Largest error after the clamp to 1.0 (``fs.error.raw_max`` for ``u0.F``), raw."""
    return min(fs.error.raw_max, 1 << fs.error.frac_bits)


def exp_rom_rows(fs: FormatSet) -> tuple[data.StructLayout, list[dict]]:
    """``(layout, rows)`` of the step generator's exp ROM, derived from :func:`~golden_model.fixed.exp_table`.

    Only the reachable addresses are stored (``0 .. k_max``). Interpolating, row ``k`` holds
    ``base = T[k]`` and ``slope = T[min(k+1, 2**n)] - T[k]`` (>= 0: the table is
    non-decreasing), the slope field as wide as the largest difference needs.
    """
    table = [int(v) for v in exp_table(fs.lut_index_bits, fs.lut_entry)]
    r = fs.lut_frac_bits
    if fs.interpolates:
        k_max = error_max(fs) >> r
        last = len(table) - 1
        slopes = [table[min(k + 1, last)] - table[k] for k in range(k_max + 1)]
        slope_bits = lut_slope_bits(fs.lut_index_bits, fs.lut_entry)  # as FormatSet.products() has it
        assert min(slopes) >= 0 and max(slopes) < 1 << slope_bits
        layout = data.StructLayout({
            "base": unsigned(fs.lut_entry.width),
            "slope": unsigned(slope_bits),
        })
        rows = [{"base": table[k], "slope": slopes[k]} for k in range(k_max + 1)]
    else:
        k_max = int(gm_shift_round(error_max(fs), r, fs.rounding)) if r else error_max(fs)
        layout = data.StructLayout({"base": unsigned(fs.lut_entry.width)})
        rows = [{"base": table[k]} for k in range(k_max + 1)]
    return layout, rows


def stepgen_idle_signal(m: Module, stepgen: StepGenerator):
    """High when the step generator holds no request: it counts requests in and results out."""
    return pending_is_zero(m, stepgen.latency, stepgen.i, stepgen.o, name="stepgen_pending")


def pending_is_zero(m: Module, latency: int, i, o, *, name: str):
    """High when a unit of ``latency`` clocks with streams ``i`` and ``o`` holds no request: a counter
    ``name`` of requests taken on ``i`` less results given on ``o`` (``o.ready`` held high)."""
    pending = Signal(range(latency + 2), name=name)
    m.d.sync += pending.eq(pending + (i.valid & i.ready) - o.valid)
    return pending == 0
