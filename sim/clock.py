"""The engine's clock in the handoff bundles: the frequency it is timed for, and its constraint files."""

from __future__ import annotations

from pathlib import Path

__all__ = ["ENGINE_TARGET_MHZ", "clock_sdc", "write_clock_constraints"]

#: The clock the engine is timed for: at :data:`~golden_model.engine_spec.image.DEFAULT_CAPACITY` it meets this on
#: the ECP5-85F (docs/engine-guard.md); ``springflat verilog``'s ``clock.sdc``.
ENGINE_TARGET_MHZ = 125.0


def clock_sdc(freq_mhz: float) -> str:
    """An SDC constraint of the one clock ``clk`` at ``freq_mhz``."""
    return f"create_clock -period {1000.0 / freq_mhz:.3f} -name clk [get_ports clk]\n"


def write_clock_constraints(out: Path, freq_mhz: float) -> None:
    """``clock.lpf`` (nextpnr-ecp5's) and ``clock.sdc`` of ``clk`` at ``freq_mhz`` into ``out``."""
    (out / "clock.lpf").write_text(f'FREQUENCY PORT "clk" {freq_mhz:g} MHZ;\n')
    (out / "clock.sdc").write_text(clock_sdc(freq_mhz))
