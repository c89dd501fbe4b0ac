"""The engine's register map as markdown, JSON and a C header, all from one :class:`RegisterMap`.

``write_exports(register_map, out_dir)`` writes ``register_map.md``, ``register_map.json`` and
``springflat_regs.h`` (next to the Verilog).  Addresses in all three are 32-bit-word addresses
(Wishbone ``adr``); the C header also gives ``SPRINGFLAT_ADDR_UNIT_BYTES`` for byte addressing.
"""

from __future__ import annotations

import json
import re
import signal
import sys
import threading
from dataclasses import replace
from pathlib import Path

from golden_model.engine_spec.image import BUS_WORD_BITS, DEFAULT_CAPACITY, LANES, EngineCapacity
from golden_model.engine_spec.register_map import ACCESS, MAGIC, REGISTER_BLOCKS, VERSION, BitField, \
    MemoryWindow, Register, RegisterMap

__all__ = ["markdown", "to_json", "c_header", "write_exports", "engine_capacity", "EXPORT_FILES"]

EXPORT_FILES = ("register_map.md", "register_map.json", "springflat_regs.h")
#: What every export's JSON holds (``magic``, the ID register's value): a directory with it holds an earlier
#: map, whose files a new one may replace (:func:`sim.outputs.holds_marker`).
EXPORT_MARKER = (EXPORT_FILES[1], "magic", MAGIC)
PREFIX = "SPRINGFLAT"


def _bits(f: BitField | tuple[int, int]) -> str:
    lsb, width = (f.lsb, f.width) if isinstance(f, BitField) else f
    return f"{lsb}" if width == 1 else f"{lsb + width - 1}:{lsb}"


def _field_text(f: BitField) -> str:
    text = f.description
    if f.fmt:
        text += f" — [{f.fmt}]" if f"[{f.fmt}]" not in text else ""
    if f.signed:
        text += " (signed)"
    if f.codes:
        text += "; codes: " + ", ".join(f"{i} {c}" for i, c in enumerate(f.codes))
    return text


def _register_rows(r: Register) -> list[str]:
    rows = []
    for f in r.fields:
        reset = (r.reset & f.mask) >> f.lsb
        rows.append(f"| `0x{r.offset:04X}` | `{r.name}` | {_bits(f)} | `{f.name}` | {f.access} | `0x{reset:X}` | "
                    f"{_field_text(f)} |")
    return rows


def _window_section(w: MemoryWindow, level: int) -> list[str]:
    lines = [f"{'#' * (level + 2)} `{w.name}` — {w.description}", "",
             f"Base `0x{w.base:05X}`, depth {w.depth}, {w.words} words per entry at a stride of {w.stride} "
             f"(entry `i`, word `k` at `0x{w.base:05X} + i·{w.stride} + k`; word 0 = bits 31:0).", "",
             "| Bits | Field | Width | Signed | Format |", "|---|---|---|---|---|"]
    for f, lsb in zip(w.fields, w.field_lsbs):
        lines.append(f"| {_bits((lsb, f.width))} | `{f.name}` | {f.width} | {'yes' if f.signed else 'no'} | "
                     f"{f.fmt or '—'} |")
    return lines + [""]


def markdown(m: RegisterMap, level: int = 1) -> str:
    """The map as markdown: the bus, a table per register block, the memory windows with their layouts
    (``level``: the title's heading level)."""
    bus = m.to_dict()["bus"]
    h = "#" * level
    lines = [
        f"{h} SpringflatEngine register map (v{VERSION[0]}.{VERSION[1]})", "",
        f"Generated from `golden_model.engine_spec.register_map.RegisterMap` for format set `{m.formats}` "
        f"(FORMAT_HASH `0x{m.format_hash:08X}`) and capacity {m.capacity.vertices} vertices, "
        f"{m.capacity.entries} entries, {m.capacity.triangles} triangles{_in_lanes(m.capacity)}. Do not edit.", "",
        f"Bus: {bus['protocol']}, {bus['data_bits']}-bit data, `adr` a {bus['address_bits']}-bit address of "
        f"{bus['address']}s (byte address >> 2), "
        f"`sel` {bus['sel']}. `err` answers: {bus['err']}.", "",
        "Access: " + "; ".join(f"`{k}` {v}" for k, v in ACCESS.items()) + ".", "",
        f"Values wider than {BUS_WORD_BITS} bits span consecutive registers, least significant word first; signed values are "
        "two's complement over the value's width.", "",
    ]
    for block in REGISTER_BLOCKS:
        lines += [f"{h}# {block.capitalize()}", "", "| Address | Register | Bits | Field | Access | Reset | Description |",
                  "|---|---|---|---|---|---|---|"]
        for r in m.registers:
            if r.block == block:
                lines += _register_rows(r)
        lines.append("")
    lines += [f"{h}# Memory windows", "", "| Window | Base | Depth | Words/entry | Stride | Size |",
              "|---|---|---|---|---|---|"]
    lines += [f"| `{w.name}` | `0x{w.base:05X}` | {w.depth} | {w.words} | {w.stride} | `0x{w.size:X}` |"
              for w in m.windows]
    lines.append("")
    for w in m.windows:
        lines += _window_section(w, level)
    return "\n".join(lines)


def to_json(m: RegisterMap) -> str:
    """The map as JSON (:meth:`RegisterMap.to_dict`; :meth:`RegisterMap.from_dict` reads it back)."""
    return json.dumps(m.to_dict(), indent=2, ensure_ascii=False) + "\n"


#: The map's texts in ASCII for the C header: a compiler that reads a source in its code page warns on any other
#: character, in a comment too (MSVC's C4819).
_ASCII = str.maketrans({"·": "*", "½": "1/2 ", "−": "-", "γ": "gamma", "Δ": "D", "φ": "phi", "ε": "eps"})


def _ascii_comment(text: str) -> str:
    """``/* text */`` in ASCII (:data:`_ASCII`, ``Σ`` as ``sum``; any other character as a ``\\u`` escape), with no
    ``*/`` inside."""
    text = re.sub("Σ(?=\\w)", "sum ", text).replace("Σ", "sum").translate(_ASCII)
    return "/* " + text.encode("ascii", "backslashreplace").decode("ascii").replace("*/", "* /") + " */"


def _in_lanes(capacity: EngineCapacity) -> str:
    return "" if capacity.lanes == 1 else f", in {capacity.lanes} lanes"


def _c_name(*parts: str) -> str:
    return "_".join([PREFIX] + [re.sub(r"[^A-Za-z0-9]", "_", p).upper() for p in parts])


def _define(name: str, value: int) -> str:
    return f"#define {name:<48} 0x{value:X}u"


def c_header(m: RegisterMap) -> str:
    """The map as a C header: register word addresses, field shifts/masks/widths (and ``_SIGNED`` for a field of
    two's-complement values), reset values, window bases/depths/strides and entry field positions, and every
    enumeration field's codes (STATUS.state, STATUS.result, MODE.mode)."""
    guard = f"{PREFIX}_REGS_H"
    lines = [f"/* SpringflatEngine register map v{VERSION[0]}.{VERSION[1]}: format set '{m.formats}', capacity "
             f"{m.capacity.vertices} vertices / {m.capacity.entries} entries / {m.capacity.triangles} triangles"
             f"{_in_lanes(m.capacity)}. */",
             "/* Generated from golden_model.engine_spec.register_map.RegisterMap; do not edit. */",
             f"/* Addresses are {BUS_WORD_BITS}-bit-word addresses (Wishbone adr): byte address = ADDR * "
             "ADDR_UNIT_BYTES. */",
             f"#ifndef {guard}", f"#define {guard}", "",
             _define(_c_name("ADDR_UNIT_BYTES"), BUS_WORD_BITS // 8), _define(_c_name("ADDR_BITS"), m.address_bits),
             _define(_c_name("MAGIC"), MAGIC),
             _define(_c_name("VERSION_MAJOR"), VERSION[0]), _define(_c_name("VERSION_MINOR"), VERSION[1]),
             _define(_c_name("FORMAT_HASH"), m.format_hash), ""]
    for r in m.registers:
        # a field of another access than its register's (CONTROL's w1p start, STATUS's ro state) says its own
        others = ", ".join(f"{f.name} {f.access}" for f in r.fields if f.access != r.access)
        access = f"{r.access}; {others}" if others else r.access
        lines += [_ascii_comment(f"{r.name} ({access}): {r.description}"), _define(_c_name(r.name, "ADDR"), r.offset),
                  _define(_c_name(r.name, "RESET"), r.reset)]
        for f in r.fields:
            lines += [_define(_c_name(r.name, f.name, "SHIFT"), f.lsb), _define(_c_name(r.name, f.name, "MASK"), f.mask),
                      _define(_c_name(r.name, f.name, "WIDTH"), f.width)]
            if f.signed:  # (two's complement in WIDTH bits: sign-extend what the mask gives)
                lines.append(_define(_c_name(r.name, f.name, "SIGNED"), 1))
        lines.append("")
    for r in m.registers:
        for f in r.fields:
            if f.codes:
                lines += [f"/* {r.name}.{f.name} codes */", *(_define(_c_name(f.name, c), i) for i, c in enumerate(f.codes)),
                          ""]
    for w in m.windows:
        # WINDOW_ in front: the entries window's base beside the ENTRIES register's address (SPRINGFLAT_ENTRIES_ADDR)
        # would read as one thing
        name = f"window_{w.name}"
        lines += [_ascii_comment(f"memory window {w.name}: {w.description}"), _define(_c_name(name, "BASE"), w.base),
                  _define(_c_name(name, "DEPTH"), w.depth), _define(_c_name(name, "WORDS"), w.words),
                  _define(_c_name(name, "STRIDE"), w.stride), _define(_c_name(name, "SIZE"), w.size)]
        for f, lsb in zip(w.fields, w.field_lsbs):
            lines += [_define(_c_name(name, f.name, "LSB"), lsb), _define(_c_name(name, f.name, "WIDTH"), f.width)]
            if f.signed:
                lines.append(_define(_c_name(name, f.name, "SIGNED"), 1))
        lines.append("")
    lines += [f"#endif /* {guard} */", ""]
    return "\n".join(lines)


def write_exports(m: RegisterMap, out_dir: str | Path) -> list[Path]:
    """Write :data:`EXPORT_FILES` into ``out_dir``; returns their paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / name for name in EXPORT_FILES]
    for path, text in zip(paths, (markdown(m), to_json(m), c_header(m))):
        path.write_text(text)
    return paths


def engine_capacity(values, fs, *, guard: bool = True, lanes: int = 1, coarse_degree: int = 0) -> EngineCapacity:
    """``--capacity V E T`` (and ``--no-guard``: ``guard`` False; ``--lanes``; ``--coarse-degree``) as an
    :class:`~golden_model.engine_spec.image.EngineCapacity` (``None``: the default depths); a capacity the
    engine's register map cannot hold, lanes with the step guard (lanes are built without it,
    ``docs/engine.md``), or a coarse space without the guard or with lanes, is a one-line :class:`ParameterError`."""
    from golden_model.params import ParameterError

    if lanes > 1 and guard:
        raise ParameterError(f"--lanes {lanes} builds the engine without the step guard: add --no-guard")
    if coarse_degree and (not guard or lanes > 1):
        given = " and ".join(flag for flag, on in (("--no-guard", not guard), (f"--lanes {lanes}", lanes > 1)) if on)
        raise ParameterError(f"--coarse-degree {coarse_degree} builds the engine's coarse space on the step guard's "
                             f"passes, with one lane: drop {given}")
    if values is None:
        return replace(DEFAULT_CAPACITY, guard=guard, lanes=lanes, coarse_degree=coarse_degree)
    try:
        capacity = EngineCapacity(*(int(v) for v in values), guard=guard, lanes=lanes, coarse_degree=coarse_degree)
        RegisterMap.build(fs, capacity)  # the address map must hold it
    except (TypeError, ValueError) as exc:  # (EngineCapacity's words without its name)
        raise ParameterError(f"--capacity V E T: {str(exc).removeprefix('EngineCapacity: ')}") from None
    check_fillable(capacity, f"--capacity {capacity.as_option()}")
    check_coarse_capacity(fs, capacity, f"--capacity {capacity.as_option()}")
    return capacity


def check_coarse_capacity(fs, capacity: EngineCapacity, what: str) -> None:
    """Refuse, in one line (:class:`ParameterError`), a coarse space at a capacity whose node memories take the
    registered select (:func:`hdl.memory_windows.needs_registered_select`), which the coarse build does not have."""
    from golden_model.params import ParameterError
    from hdl.memory_windows import needs_registered_select

    if capacity.coarse_degree and needs_registered_select(fs, capacity):
        raise ParameterError(f"{what}: the engine's coarse space is built only where the node memories are one "
                             f"block RAM bank each (up to {DEFAULT_CAPACITY.vertices} vertices in 'default'): "
                             "use a smaller capacity, or --coarse-degree 0")


def beyond_the_85f(capacity: EngineCapacity) -> str | None:
    """A note for a capacity with a memory deeper than :data:`~golden_model.engine_spec.image.LARGEST_85F_CAPACITY`'s:
    its Verilog export and simulation build take long (at 100,000 vertices, over 10 minutes before the run starts),
    or ``None``. (Whether it fits a device is ``springflat verilog``'s count, :func:`sim.synth.ecp5_overflow`.)"""
    from golden_model.engine_spec.image import LARGEST_85F_CAPACITY as largest

    if all(getattr(capacity, d) <= getattr(largest, d) for d in ("vertices", "entries", "triangles")):
        return None
    return (f"capacity {capacity.as_option()} has a memory deeper than {largest.as_option()}'s, the largest engine "
            "the LFE5U-85F holds in the default formats (docs/synthesis.md): its export and simulation build take "
            "long, minutes and more with depth (over 10 minutes at 100,000 vertices)")


def check_fillable(capacity: EngineCapacity, given: str) -> None:
    """A one-line :class:`ParameterError` (naming ``given``, where the capacity came from) for depths that hold
    fewer vertices than the capacity says, or no mesh: a typo's memories."""
    from golden_model.params import ParameterError

    v, fillable = max(capacity.vertices, 3), capacity.fillable_vertices  # (a mesh has a triangle at least)
    if fillable < v:
        held = (f"at most {fillable} vertices (give more entries or triangles, or fewer vertices)" if fillable >= 3
                else "no mesh")
        entries, triangles = EngineCapacity.least_for(v)
        raise ParameterError(f"{given}: a disk mesh of {v} vertices has at least {entries} neighbour entries and "
                             f"{triangles} triangle{'s' if triangles > 1 else ''}; these depths hold {held}")


def main(argv: list[str] | None = None) -> int:
    """``python -m sim.register_map_export --formats PRESET|FILE --capacity V E T [--lanes K] --out DIR``."""
    from golden_model.fixed.engine import load_formats
    from golden_model.fixed.measures import FixedPointError
    from golden_model.fixed.formats_set import FormatSet
    from golden_model.mesh import one_line
    from golden_model.params import ParameterError

    from .exit_codes import STOP_SIGNALS, answered_signals
    from .outputs import (OutputError, atomic_directory, check_build_so_far, describe_os_error, holds_marker,
                          on_interrupt, received_signal, reset_interrupted)
    from .run_options import CommandParser, OneOutput, integer_argument, path_argument

    prog = "python -m sim.register_map_export"
    parser = CommandParser(prog=prog, error_name=prog, description=main.__doc__)
    parser.add_argument("--formats", default="default")
    parser.add_argument("--capacity", nargs=3, type=integer_argument, metavar=("VERTICES", "ENTRIES", "TRIANGLES"),
                        default=(DEFAULT_CAPACITY.vertices, DEFAULT_CAPACITY.entries, DEFAULT_CAPACITY.triangles),
                        help="the engine's capacity (default: the one springflat verilog and synth build)")
    parser.add_argument("--lanes", type=integer_argument, choices=LANES, default=1, metavar="K",
                        help="the map of an engine of K lanes (docs/engine.md, 'Lanes'; default 1)")
    parser.add_argument("--out", required=True, type=path_argument, action=OneOutput)
    args = parser.parse_args(argv)
    reset_interrupted()
    # Ctrl-C, kill or a hang-up: one line and the command's status (no traceback, no directory half built)
    previous = ({name: signal.signal(getattr(signal, name), on_interrupt) for name in answered_signals()}
                if threading.current_thread() is threading.main_thread() else {})
    try:
        try:
            formats = load_formats(args.formats)
            # (--capacity's checks); the map of K > 1 lanes is the unguarded engine's, the one lanes build
            capacity = engine_capacity(args.capacity, formats, guard=args.lanes == 1, lanes=args.lanes)
            m = RegisterMap.build(formats, capacity)
        except (FixedPointError, ParameterError, ValueError) as exc:
            parser.exit(2, f"{parser.prog}: error: {exc}\n")
        except OSError as exc:  # a --formats file that cannot be read (a FIFO, a directory)
            parser.exit(2, f"{parser.prog}: error: cannot read --formats '{args.formats}': {describe_os_error(exc)}\n")
        out = args.out
        try:
            inputs = [("--formats", None if FormatSet.names_preset(args.formats) else Path(args.formats))]
            # a namesake of the user's is refused, not replaced: an earlier export's (or bundle's) files are ours
            owned = EXPORT_FILES if holds_marker(out, EXPORT_MARKER) else ()
            with atomic_directory(out, inputs=inputs, owned=owned) as build:  # all three files in place, or none
                names = [path.name for path in write_exports(m, build)]
                check_build_so_far()  # (a --formats file it would replace is named as such first)
        except OutputError as exc:
            parser.exit(2, f"{parser.prog}: error: {one_line(str(exc))}\n")
    except KeyboardInterrupt:
        line, status = STOP_SIGNALS[received_signal().name]
        print(f"{parser.prog}: {line}", file=sys.stderr)
        return status
    finally:
        for name, before in previous.items():
            signal.signal(getattr(signal, name), before)
        if argv is not None:  # a caller running it in-process goes on: its own writes are not this command's
            reset_interrupted()
    for name in names:
        print(out / name)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
