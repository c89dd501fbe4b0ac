"""The engine on a board: the Radiona ULX3S with an LFE5U-85F (``docs/board.md``).

* :class:`BoardCore`: everything in the engine's clock domain: the UART bridge
  (:class:`hdl.uart_bridge.UartBridge`), :class:`~hdl.engine.SpringflatEngine` behind it, and
  :class:`StateLeds`. This is what the simulations run (no PLL, no pins).
* :class:`EcpPll`: the ECP5 ``EHXPLLL`` from the board oscillator to the engine clock, with dividers
  computed by :func:`pll_config`.
* :class:`Ulx3sTop`: the board top for amaranth-boards' ULX3S platform (:class:`Ulx3s85fPlatform`):
  25 MHz oscillator → PLL → ``sync`` domain (held in reset until the PLL locks), the FTDI UART pins,
  the eight LEDs (:data:`LEDS`).
"""

from __future__ import annotations

from dataclasses import dataclass

from amaranth.hdl import ClockDomain, Const, Elaboratable, Instance, Module, Signal
from amaranth.lib import io, wiring
from amaranth.lib.cdc import ResetSynchronizer
from amaranth.lib.wiring import In, Out

from golden_model.fixed import FormatSet
from golden_model.engine_spec import uart_protocol as protocol
from golden_model.engine_spec.image import RESULTS, EngineCapacity
from golden_model.engine_spec.register_map import STATES, RegisterMap

from .engine import SpringflatEngine
from .parameters import check_int
from .uart_bridge import UartBridge, timeout_clocks, uart_divisor
from .wishbone import DATA_WIDTH

__all__ = ["LEDS", "PllConfig", "pll_config", "EcpPll", "StateLeds", "BoardCore", "Ulx3sTop", "Ulx3s85fPlatform",
           "OSCILLATOR_HZ", "ENGINE_CLOCK_HZ"]

#: The ULX3S's oscillator. The engine clock the top asks the PLL for is the protocol's
#: :data:`~golden_model.engine_spec.uart_protocol.ENGINE_CLOCK_HZ`; ``synth --board --freq`` builds for another.
OSCILLATOR_HZ = 25e6
ENGINE_CLOCK_HZ = protocol.ENGINE_CLOCK_HZ

#: What each LED shows, LED 0 first (BoardCore drives 0-6, the top adds the PLL's lock on 7).
LEDS = ("heartbeat", "idle", "running", "done", "error", "uart_rx", "uart_tx", "pll_locked")


# ---------------------------------------------------------------------------------------------- the PLL
@dataclass(frozen=True)
class PllConfig:
    """``EHXPLLL`` dividers with the feedback from CLKOP: f_out = f_in / refclk_div × feedback_div,
    f_vco = f_out × output_div."""

    input_hz: float
    refclk_div: int  # CLKI_DIV
    feedback_div: int  # CLKFB_DIV
    output_div: int  # CLKOP_DIV

    @property
    def pfd_hz(self) -> float:
        return self.input_hz / self.refclk_div

    @property
    def output_hz(self) -> float:
        return self.pfd_hz * self.feedback_div

    @property
    def vco_hz(self) -> float:
        return self.output_hz * self.output_div


#: ECP5 sysCLOCK PLL ranges (Lattice FPGA-DS-02012, EHXPLLL): phase detector input, VCO, dividers.
PFD_RANGE_HZ = (3.125e6, 400e6)
VCO_RANGE_HZ = (400e6, 800e6)
OUTPUT_RANGE_HZ = (3.125e6, 400e6)
DIVIDER_MAX = {"refclk_div": 128, "feedback_div": 80, "output_div": 128}


def pll_config(input_hz: float, output_hz: float, tolerance: float = 0.0) -> PllConfig:
    """The dividers whose output is nearest ``output_hz`` (then: the VCO nearest 600 MHz, the middle of
    its range; then the smallest reference divider), refused beyond ``tolerance`` (relative)."""
    if not OUTPUT_RANGE_HZ[0] <= output_hz <= OUTPUT_RANGE_HZ[1]:
        raise ValueError(f"the PLL output must be {OUTPUT_RANGE_HZ[0] / 1e6:g}-{OUTPUT_RANGE_HZ[1] / 1e6:g} MHz, "
                         f"not {output_hz / 1e6:g} MHz")
    best, best_key = None, None
    for refclk in range(1, DIVIDER_MAX["refclk_div"] + 1):
        if not PFD_RANGE_HZ[0] <= input_hz / refclk <= PFD_RANGE_HZ[1]:
            continue
        for feedback in range(1, DIVIDER_MAX["feedback_div"] + 1):
            out = input_hz / refclk * feedback
            for output in range(1, DIVIDER_MAX["output_div"] + 1):
                vco = out * output
                if not VCO_RANGE_HZ[0] <= vco <= VCO_RANGE_HZ[1]:
                    continue
                key = (round(abs(out - output_hz), 3), abs(vco - 600e6), refclk)
                if best_key is None or key < best_key:
                    best, best_key = PllConfig(input_hz, refclk, feedback, output), key
    if best is None or abs(best.output_hz - output_hz) > tolerance * output_hz:
        near = f" (nearest {best.output_hz / 1e6:.4f} MHz)" if best else ""
        raise ValueError(f"the PLL cannot make {output_hz / 1e6:g} MHz from {input_hz / 1e6:g} MHz{near}")
    return best


class EcpPll(wiring.Component):
    """One ``EHXPLLL``: ``clk_in`` at ``input_hz`` to ``clk_out`` at ``output_hz`` (exactly, or refused), the
    feedback from CLKOP, phase 0 (CLKOP_CPHASE = CLKOP_DIV − 1, Lattice's convention).

    **Latency**: ``locked`` rises some hundreds of microseconds after the input clock starts (the
    device's lock time); the top holds the engine's domain in reset until then.

    Members
    -------
    clk_in : ``In(1)``; clk_out, locked : ``Out(1)``
    """

    def __init__(self, input_hz: float, output_hz: float):
        self.config = pll_config(input_hz, output_hz)
        super().__init__({"clk_in": In(1), "clk_out": Out(1), "locked": Out(1)})

    def elaborate(self, platform):
        m = Module()
        c = self.config
        m.submodules.pll = Instance(
            "EHXPLLL",
            a_FREQUENCY_PIN_CLKI=f"{c.input_hz / 1e6:g}", a_FREQUENCY_PIN_CLKOP=f"{c.output_hz / 1e6:g}",
            a_ICP_CURRENT="6", a_LPF_RESISTOR="16", a_MFG_ENABLE_FILTEROPAMP="1", a_MFG_GMCREF_SEL="2",
            p_PLLRST_ENA="DISABLED", p_INTFB_WAKE="DISABLED", p_STDBY_ENABLE="DISABLED",
            p_DPHASE_SOURCE="DISABLED", p_OUTDIVIDER_MUXA="DIVA", p_OUTDIVIDER_MUXB="DIVB",
            p_OUTDIVIDER_MUXC="DIVC", p_OUTDIVIDER_MUXD="DIVD",
            p_CLKI_DIV=c.refclk_div, p_CLKFB_DIV=c.feedback_div, p_FEEDBK_PATH="CLKOP",
            p_CLKOP_ENABLE="ENABLED", p_CLKOP_DIV=c.output_div, p_CLKOP_CPHASE=c.output_div - 1, p_CLKOP_FPHASE=0,
            i_CLKI=self.clk_in, i_CLKFB=self.clk_out, i_RST=Const(0, 1), i_STDBY=Const(0, 1),
            i_PHASESEL0=Const(0, 1), i_PHASESEL1=Const(0, 1), i_PHASEDIR=Const(1, 1), i_PHASESTEP=Const(1, 1),
            i_PHASELOADREG=Const(1, 1), i_PLLWAKESYNC=Const(0, 1), i_ENCLKOP=Const(0, 1),
            o_CLKOP=self.clk_out, o_LOCK=self.locked)
        return m


# ---------------------------------------------------------------------------------------------- the LEDs
class StateLeds(wiring.Component):
    """The engine's state for the LEDs, followed from its bus (the engine has no state port).

    A START written to CONTROL (acknowledged) shows ``running``, an ABORT ``idle``, the interrupt line
    ``done`` (the host starts with ``irq_enable``); every STATUS read (acknowledged) shows the state it
    read. ``error`` is the bridge's last answer being an error, or the last STATUS read showing a run that
    ended as diverged, no-mesh or bad-constants. ``heartbeat`` toggles every ``2**heartbeat_bits``
    clocks (the clock runs); ``uart_rx``/``uart_tx`` light for ``2**blink_bits`` clocks after a byte.

    **Latency**: three clocks from the bus answer (or irq) to the LEDs (every input is registered first,
    as it comes from across the device; the state; the LED register). The state shown is what the host
    last saw, plus ``done`` from the interrupt.

    Members
    -------
    cyc, stb, we, ack : ``In(1)``; adr : ``In(addr_width)``; dat_w, dat_r : ``In(DATA_WIDTH)``: the bus, watched.
    irq, bridge_error, rx_byte, tx_byte : ``In(1)``
    leds : ``Out(7)``, :data:`LEDS` 0-6.
    """

    def __init__(self, register_map: RegisterMap, addr_width: int, *, heartbeat_bits: int, blink_bits: int):
        for name, value in (("heartbeat_bits", heartbeat_bits), ("blink_bits", blink_bits)):
            check_int(name, value)
        self.map, self.heartbeat_bits, self.blink_bits = register_map, heartbeat_bits, blink_bits
        super().__init__({"cyc": In(1), "stb": In(1), "we": In(1), "ack": In(1), "adr": In(addr_width),
                          "dat_w": In(DATA_WIDTH), "dat_r": In(DATA_WIDTH), "irq": In(1), "bridge_error": In(1),
                          "rx_byte": In(1), "tx_byte": In(1), "leds": Out(len(LEDS) - 1)})

    def elaborate(self, platform):
        m = Module()
        control, status = self.map.register("CONTROL"), self.map.register("STATUS")
        field = {(r.name, f.name): f for r in (control, status) for f in r.fields}
        state_f, result_f = field[("STATUS", "state")], field[("STATUS", "result")]
        start_f, abort_f = field[("CONTROL", "start")], field[("CONTROL", "abort")]

        # every input through a flip-flop first: the bus and the pulses come from across the device
        names = ("cyc", "stb", "we", "ack", "adr", "dat_w", "dat_r", "irq", "bridge_error", "rx_byte", "tx_byte")
        seen = {}
        for name in names:
            port = getattr(self, name)
            seen[name] = Signal.like(port, name=f"{name}_q")
            m.d.sync += seen[name].eq(port)
        state = Signal(range(len(STATES)))  # reset: idle
        failed = Signal()
        answered = seen["cyc"] & seen["stb"] & seen["ack"]
        with m.If(answered & seen["we"] & (seen["adr"] == control.offset)):
            with m.If(seen["dat_w"][abort_f.lsb]):
                m.d.sync += state.eq(STATES.index("idle"))
            with m.Elif(seen["dat_w"][start_f.lsb]):
                m.d.sync += [state.eq(STATES.index("running")), failed.eq(0)]
        with m.Elif(answered & ~seen["we"] & (seen["adr"] == status.offset)):
            dat_r = seen["dat_r"]
            result = dat_r[result_f.lsb:result_f.lsb + result_f.width]
            m.d.sync += [state.eq(dat_r[state_f.lsb:state_f.lsb + state_f.width]),
                         failed.eq((result == RESULTS.index("diverged")) | (result == RESULTS.index("no-mesh"))
                                   | (result == RESULTS.index("bad-constants")))]
        with m.Elif(seen["irq"]):
            m.d.sync += state.eq(STATES.index("done"))

        heartbeat = Signal(self.heartbeat_bits + 1)
        m.d.sync += heartbeat.eq(heartbeat + 1)
        blinks = []
        for pulse in (seen["rx_byte"], seen["tx_byte"]):
            timer = Signal(self.blink_bits)
            with m.If(pulse):
                m.d.sync += timer.eq(~0)
            with m.Elif(timer != 0):
                m.d.sync += timer.eq(timer - 1)
            blinks.append(timer != 0)
        lit = {"heartbeat": heartbeat[-1], "idle": state == STATES.index("idle"),
               "running": state == STATES.index("running"), "done": state == STATES.index("done"),
               "error": seen["bridge_error"] | failed, "uart_rx": blinks[0], "uart_tx": blinks[1]}
        for i, name in enumerate(LEDS[:-1]):
            m.d.sync += self.leds[i].eq(lit[name])
        return m


# ---------------------------------------------------------------------------------------------- the core
class BoardCore(wiring.Component):
    """The UART bridge, the engine and the LEDs, in one clock domain (``sync``): the board top without its
    PLL and pins, and what the simulations run.

    Latency and throughput: :class:`~hdl.uart_bridge.UartBridge`'s and the engine's (``docs/board.md``).

    Parameters
    ----------
    fs, capacity :
        The engine's (:class:`~hdl.engine.SpringflatEngine`).
    divisor : int
        Clocks per UART bit (:func:`~hdl.uart_bridge.uart_divisor`).
    timeout : int
        The bridge's inter-byte timeout in clocks.
    heartbeat_bits, blink_bits : int
        :class:`StateLeds`'s.

    Members
    -------
    rx : ``In(1)``; tx : ``Out(1)``, the UART line.
    leds : ``Out(7)``, :data:`LEDS` 0-6.
    """

    def __init__(self, fs: FormatSet | str, capacity: EngineCapacity, *, divisor: int, timeout: int,
                 heartbeat_bits: int = 26, blink_bits: int = 22):
        fs = FormatSet.preset(fs) if isinstance(fs, str) else fs
        self.engine = SpringflatEngine(fs, capacity)
        self.register_map = RegisterMap.build(fs, capacity)
        addr_width = self.engine.signature.members["bus"].signature.addr_width
        self.bridge = UartBridge(divisor=divisor, addr_width=addr_width, timeout=timeout)
        self.state_leds = StateLeds(self.register_map, addr_width, heartbeat_bits=heartbeat_bits,
                                    blink_bits=blink_bits)
        super().__init__({"rx": In(1, init=1), "tx": Out(1, init=1), "leds": Out(len(LEDS) - 1)})

    def elaborate(self, platform):
        m = Module()
        m.submodules.bridge = bridge = self.bridge
        m.submodules.engine = engine = self.engine
        m.submodules.state_leds = leds = self.state_leds
        wiring.connect(m, bridge.bus, engine.bus)
        bus = bridge.bus
        m.d.comb += [bridge.rx.eq(self.rx), self.tx.eq(bridge.tx), self.leds.eq(leds.leds),
                     leds.cyc.eq(bus.cyc), leds.stb.eq(bus.stb), leds.we.eq(bus.we), leds.ack.eq(bus.ack),
                     leds.adr.eq(bus.adr), leds.dat_w.eq(bus.dat_w), leds.dat_r.eq(bus.dat_r),
                     leds.irq.eq(engine.irq), leds.bridge_error.eq(bridge.error),
                     leds.rx_byte.eq(bridge.rx_byte), leds.tx_byte.eq(bridge.tx_byte)]
        return m


# ---------------------------------------------------------------------------------------------- the board
def _ulx3s_85f():
    from amaranth_boards.ulx3s import ULX3S_85F_Platform

    class Ulx3s85fPlatform(ULX3S_85F_Platform):
        """amaranth-boards' ULX3S-85F, asking the engine for ECP5 primitives (``hdl.dsp.dsp_target``:
        MULT18X18D multipliers, DP16KD block RAMs read through their output registers)."""

        dsp = "ecp5"

    return Ulx3s85fPlatform


def __getattr__(name):  # the platform class needs amaranth-boards, imported only when asked for
    if name == "Ulx3s85fPlatform":
        return _ulx3s_85f()
    raise AttributeError(name)


class Ulx3sTop(Elaboratable):
    """The ULX3S-85F top: ``clk25`` → :class:`EcpPll` → the ``sync`` domain at ``clock_hz``, in reset until
    the PLL locks (:class:`~amaranth.lib.cdc.ResetSynchronizer`); :class:`BoardCore` on the FTDI UART
    (``uart`` 0: ``rx`` M1, ``tx`` L4) at ``baud``; the LEDs ``led`` 0-7 as :data:`LEDS`."""

    def __init__(self, fs: FormatSet | str, capacity: EngineCapacity, *, clock_hz: float = ENGINE_CLOCK_HZ,
                 baud: int = protocol.DEFAULT_BAUD):
        self.clock_hz, self.baud = clock_hz, baud
        self.pll = EcpPll(OSCILLATOR_HZ, clock_hz)
        self.core = BoardCore(fs, capacity, divisor=uart_divisor(clock_hz, baud), timeout=timeout_clocks(clock_hz),
                              heartbeat_bits=max(1, round(clock_hz).bit_length() - 2),
                              blink_bits=max(1, round(clock_hz * 0.05).bit_length()))

    #: Flip-flops between the reset synchroniser and the ``sync`` domain's reset.
    RESET_STAGES = 2

    def elaborate(self, platform):
        m = Module()
        m.domains.sync = sync = ClockDomain("sync")
        m.submodules.pll = pll = self.pll
        m.submodules.core = core = self.core
        # The reset: synchronised to the PLL's clock in the `lock` domain, then RESET_STAGES plain
        # flip-flops (high from configuration) before it is the `sync` domain's. The synchroniser sits
        # by the PLL, in a corner of the die; the reset reaches some 2,000 flip-flops all over it, and
        # a route from that corner to the far one takes most of a clock. The stages let the placer put
        # the last one amid the flip-flops it resets (the links before it have a whole clock each).
        m.domains.lock = lock = ClockDomain("lock", local=True)
        m.submodules.reset_sync = ResetSynchronizer(~pll.locked, domain="lock")
        stages = [Signal(init=1, reset_less=True, name=f"reset_stage{k}") for k in range(self.RESET_STAGES)]
        m.d.lock += [stages[0].eq(lock.rst), *(stages[k].eq(stages[k - 1]) for k in range(1, len(stages)))]
        m.submodules.clk25 = clk25 = io.Buffer("i", platform.request("clk25", 0, dir="-"))
        m.d.comb += [pll.clk_in.eq(clk25.i), sync.clk.eq(pll.clk_out), lock.clk.eq(pll.clk_out),
                     sync.rst.eq(stages[-1])]
        platform.add_clock_constraint(sync.clk, self.clock_hz)
        uart = platform.request("uart", 0, dir="-")
        m.submodules.uart_rx = uart_rx = io.Buffer("i", uart.rx)
        m.submodules.uart_tx = uart_tx = io.Buffer("o", uart.tx)
        m.d.comb += [core.rx.eq(uart_rx.i), uart_tx.o.eq(core.tx)]
        for i in range(len(LEDS)):
            m.submodules[f"led_{i}"] = led = io.Buffer("o", platform.request("led", i, dir="-"))
            m.d.comb += led.o.eq(core.leds[i] if i < len(LEDS) - 1 else pll.locked)
        return m
