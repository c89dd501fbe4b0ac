"""A ROM read in two registered clocks: generic RTL or ECP5 ``DP16KD`` block RAM with its output register.

:func:`registered_rom` returns ``table[addr]`` two clocks after ``addr`` (the address is
registered, then the data). In generic RTL that is an :class:`amaranth.lib.memory.Memory` read
port (its address register) and a flip-flop on its data. Yosys's ``synth_ecp5`` maps that
to a ``DP16KD`` with ``REGMODE_A = "NOREG"`` and leaves the data register in the fabric: the
block RAM's unregistered clock-to-output (~5.6 ns) plus the route to that flip-flop then
limits the clock, and Yosys does not infer the output
register. Elaborated with :data:`hdl.dsp.ECP5` as the platform, the ROM is therefore a row of
``DP16KD`` instances with ``REGMODE_A = "OUTREG"``, one per column slice of the word, in the
deepest configuration that holds the table. Both forms have the same function and latency;
the ECP5 flavour is simulated against the golden model with a model of the primitive
(``sim/models/DP16KD.v``) whose memory packing is checked against Yosys's own mapping.
"""

from __future__ import annotations

from amaranth.hdl import ClockSignal, Const, Instance, Module, Signal, Value, unsigned
from amaranth.lib.memory import Memory

from .dsp import dsp_target
from .fixedpoint import FormatSetNotBuildable

__all__ = ["DP16KD_CONFIGS", "ENTRY_BANK_DEPTH", "dp16kd", "dp16kd_config", "dp16kd_initvals", "dp16kd_port",
           "registered_rom"]

#: ``DP16KD`` port widths and their depths (16 Kib, 18 Kib with the ninth bits).
DP16KD_CONFIGS = ((18, 1024), (9, 2048), (4, 4096), (2, 8192), (1, 16384))
#: Words per bank of the engine's entry memory: DP16KD's 2K×9 mode, the deepest in which Yosys maps a
#: wide word as a row of block RAMs side by side, without a cascade multiplexer behind them.
ENTRY_BANK_DEPTH = dict(DP16KD_CONFIGS)[9]
#: The primitive's data and address pins per port (the device's, not a format's).
DP16KD_DATA_PINS, DP16KD_ADDRESS_PINS = 18, 14


def dp16kd_config(depth: int) -> tuple[int, int]:
    """The widest ``(data width, address bits)`` configuration with at least ``depth`` words."""
    for width, words in DP16KD_CONFIGS:
        if words >= depth:
            return width, (words - 1).bit_length()
    raise FormatSetNotBuildable(f"a ROM of {depth} words does not fit one DP16KD column (at most 16384)")


def dp16kd_initvals(words, width: int) -> dict[str, str]:
    """``INITVAL_00`` … ``INITVAL_3F`` for ``words`` (ints of ``width`` bits) in a ``width``-wide DP16KD.

    Each INITVAL holds 16 rows of 18 bits (in 20-bit groups). A row holds one 18-bit word,
    two 9-bit words, or narrow words packed into the low 8 bits of each 9-bit byte, the lower
    address in the lower bits: the packing Yosys's ``memory_libmap`` produces.
    """
    per_byte = 1 if width >= 9 else 8 // width
    positions = [0] if width == 18 else [byte * 9 + j * width for byte in (0, 1) for j in range(per_byte)]
    rows = [0] * 1024
    for address, word in enumerate(words):
        row, k = divmod(address, len(positions))
        rows[row] |= (int(word) & ((1 << width) - 1)) << positions[k]
    return {f"p_INITVAL_{n:02X}": Const(sum(rows[n * 16 + i] << (20 * i) for i in range(16)), 320)
            for n in range(64)}


def dp16kd_port(port: str, *, clock, address, write_data=None, read_data=None, write_enable=None,
                clock_enable=None, output_enable=None) -> dict:
    """The ``Instance`` pins of one ``DP16KD`` port (``"A"`` or ``"B"``): its clock, 14-bit
    ``address``, ``write_data`` (18 bits; ``None``: zeros) and ``read_data`` (an 18-bit signal for
    ``DO``; ``None``: unconnected), the write, clock and output-register enables (``None``: 0, 1, 1);
    its reset and chip selects low."""
    zero, one = Const(0, 1), Const(1, 1)
    pins = {f"i_CLK{port}": clock, f"i_WE{port}": zero if write_enable is None else write_enable,
            f"i_CE{port}": one if clock_enable is None else clock_enable,
            f"i_OCE{port}": one if output_enable is None else output_enable,
            f"i_RST{port}": zero, **{f"i_CS{port}{i}": zero for i in range(3)}}
    pins.update({f"i_AD{port}{i}": address[i] for i in range(DP16KD_ADDRESS_PINS)})
    pins.update({f"i_DI{port}{i}": zero if write_data is None else write_data[i] for i in range(DP16KD_DATA_PINS)})
    if read_data is not None:
        pins.update({f"o_DO{port}{i}": read_data[i] for i in range(DP16KD_DATA_PINS)})
    return pins


def dp16kd(width: int, *, regmode_a: str = "NOREG", regmode_b: str = "NOREG", initvals: dict | None = None,
           **pins) -> Instance:
    """A ``DP16KD`` with both ports ``width`` bits wide, the given output-register modes, write mode
    NORMAL, no chip-select decode and no global reset; ``pins`` from :func:`dp16kd_port`."""
    return Instance(
        "DP16KD",
        p_DATA_WIDTH_A=width, p_DATA_WIDTH_B=width, p_REGMODE_A=regmode_a, p_REGMODE_B=regmode_b,
        p_RESETMODE="SYNC", p_ASYNC_RESET_RELEASE="SYNC", p_CSDECODE_A="0b000", p_CSDECODE_B="0b000",
        p_WRITEMODE_A="NORMAL", p_WRITEMODE_B="NORMAL", p_GSR="DISABLED", **(initvals or {}), **pins)


def registered_rom(m: Module, table, width: int, addr, *, name: str, enable=None, platform=None) -> Value:
    """``table[addr]`` (``width`` bits) two clocks later; ``enable`` is every register's clock enable."""
    addr = Value.cast(addr)
    data = Signal(unsigned(width), name=f"{name}_data", reset_less=True)
    enable = Const(1, 1) if enable is None else enable
    if dsp_target(platform) != "ecp5":
        m.submodules[name] = rom = Memory(shape=unsigned(width), depth=len(table), init=list(table))
        port = rom.read_port()
        m.d.comb += [port.en.eq(enable), port.addr.eq(addr)]
        with m.If(enable):
            m.d.sync += data.eq(port.data)
        return data
    slice_width, address_bits = dp16kd_config(len(table))
    if len(addr) > address_bits:
        raise ValueError(f"{name}: a {len(addr)}-bit address for a {len(table)}-word ROM")
    ada = Signal(DP16KD_ADDRESS_PINS, name=f"{name}_ada")
    m.d.comb += ada.eq(addr << (DP16KD_ADDRESS_PINS - address_bits))
    for k, lo in enumerate(range(0, width, slice_width)):
        bits = min(slice_width, width - lo)
        doa = Signal(DP16KD_DATA_PINS, name=f"{name}{k}_doa")
        m.submodules[f"{name}{k}"] = dp16kd(
            slice_width, regmode_a="OUTREG",
            initvals=dp16kd_initvals([(int(w) >> lo) for w in table], slice_width),
            **dp16kd_port("A", clock=ClockSignal(), address=ada, read_data=doa, clock_enable=enable,
                          output_enable=enable),
            **dp16kd_port("B", clock=Const(0, 1), address=Const(0, DP16KD_ADDRESS_PINS), clock_enable=Const(0, 1),
                          output_enable=Const(0, 1)))
        m.d.comb += data[lo:lo + bits].eq(doa[:bits])
    return data
