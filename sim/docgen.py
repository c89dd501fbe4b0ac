"""Generated blocks in the docs: tables the code states once, written into ``docs/*.md`` by a command.

A block is delimited in the markdown by::

    <!-- generated: NAME -->
    ...
    <!-- end generated -->

and its text is ``GENERATORS[NAME]()``. ``python -m sim.docgen`` rewrites every block in ``docs/``;
``python -m sim.docgen --check`` (and ``tests/sim/test_docgen.py``) fails, naming the file and block, when
one is out of step with the code.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path
from typing import Callable

from golden_model.engine_spec.image import DEFAULT_CAPACITY

DOCS = Path(__file__).resolve().parent.parent / "docs"
BLOCK = re.compile(r"(<!-- generated: (?P<name>[\w-]+) -->\n)(?P<body>.*?)(<!-- end generated -->)", re.DOTALL)


def _run_modes() -> str:
    from golden_model.modes import modes_table

    return modes_table()


def _guard_constants() -> str:
    from golden_model import guard

    rows = ["| constant | value | meaning |", "|---|---|---|"]
    for name in ("GUARD_LEVELS", "FLOOR_SHIFT", "FLOOR_MIN_SHIFT", "SCALE_GROW_AFTER", "SCALE_MAX_SHIFT",
                 "ENERGY_WINDOW", "ENERGY_FLOOR"):
        doc = _constant_doc(guard, name)
        rows.append(f"| `{name}` | {getattr(guard, name):g} | {doc} |")
    return "\n".join(rows)


def _constant_doc(module, name: str) -> str:
    """The ``#:`` comment above ``name = ...`` in ``module``'s source, joined into one line."""
    lines = Path(module.__file__).read_text(encoding="utf-8").splitlines()
    index = next(i for i, line in enumerate(lines) if line.startswith(f"{name} ="))
    comment = []
    while index > 0 and lines[index - 1].startswith("#:"):
        index -= 1
        comment.insert(0, lines[index][2:].strip())
    return " ".join(comment)


#: The format set and capacity of docs/engine.md's register map: the engine springflat verilog and synth
#: build by default, so that its addresses are the ones a user meets.
DOC_MAP = ("default", DEFAULT_CAPACITY)


def _register_map() -> str:
    from golden_model.engine_spec.register_map import RegisterMap
    from golden_model.fixed import FormatSet
    from sim.register_map_export import markdown

    formats, capacity = DOC_MAP
    return markdown(RegisterMap.build(FormatSet.preset(formats), capacity), level=3)


def _tables() -> dict[str, Callable[[], str]]:
    from functools import partial

    from sim import doc_tables as t

    return {
        "format-presets": t.format_presets,
        "knob-domains": t.knob_domains,
        "resolution-scales": t.resolution_scales,
        "accuracy-bounds": t.accuracy_bounds,
        "rsqrt-accuracy": t.rsqrt_accuracy,
        "step-accuracy": t.step_accuracy,
        "preset-costs": t.preset_costs,
        "signal-classes": t.signal_classes,
        "node-update-contract": t.node_update_contract,
        "node-update-flip-flops": t.node_update_flip_flops,
        "unit-figures": t.unit_figures,
        "synth-components": t.synth_components,
        "datapath-throughput": t.datapath_throughput,
        "synthesis-ecp5-components": partial(t.synthesis_components, "ecp5"),
        "synthesis-ecp5-engine": partial(t.synthesis_engine, "ecp5"),
        "synthesis-ice40-components": partial(t.synthesis_components, "ice40"),
    }


def _host_scaling() -> str:
    from .export import host_scaling_markdown

    return host_scaling_markdown()


GENERATORS: dict[str, Callable[[], str]] = {
    "run-modes": _run_modes,
    "host-scaling": _host_scaling,
    "guard-constants": _guard_constants,
    "register-map": _register_map,
    **_tables(),
}


def render(text: str, generators: dict[str, Callable[[], str]] = GENERATORS) -> str:
    """``text`` with every generated block's body replaced by its generator's output."""
    def replace(match: re.Match) -> str:
        name = match.group("name")
        if name not in generators:
            raise KeyError(f"no generator for block '{name}'")
        return f"{match.group(1)}{generators[name]().rstrip()}\n{match.group(4)}"

    return BLOCK.sub(replace, text)


def stale_blocks(docs: Path = DOCS) -> list[str]:
    """``file: block`` for every generated block whose text differs from what the code generates now."""
    stale = []
    for path in sorted(docs.glob("*.md")):
        text = path.read_text(encoding="utf-8")
        for match in BLOCK.finditer(text):
            name = match.group("name")
            if render(match.group(0)) != match.group(0):
                stale.append(f"{path.name}: {name}")
    return stale


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m sim.docgen", description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="only report blocks that are out of step (exit 1)")
    args = parser.parse_args(argv)
    if args.check:
        stale = stale_blocks()
        for entry in stale:
            print(f"out of step: {entry}", file=sys.stderr)
        return 1 if stale else 0
    for path in sorted(DOCS.glob("*.md")):
        text = path.read_text(encoding="utf-8")
        new = render(text)
        if new != text:
            path.write_text(new, encoding="utf-8")
            print(f"rewrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
