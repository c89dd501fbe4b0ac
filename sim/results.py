"""The measured synthesis results: one CSV file, written from ``springflat synth --json`` reports.

``docs/results/synthesis.csv`` holds the latest place-and-route result of every configuration
measured (target, format set, component, capacity, seed), one row each, with the date and the
command that produced it. ``docs/synthesis.md`` renders its tables from this file
(:mod:`sim.docgen`), so a figure in the docs is always a row here.

Add a run with::

    springflat synth --target ecp5 --components springflat_core --seed 2 --out DIR
    python -m sim.results record DIR/synth_report.json [--date YYYY-MM-DD]

A row for the same configuration is replaced (git keeps the history); ``python -m sim.docgen`` then
rewrites the tables.
"""

from __future__ import annotations

import argparse
import csv
import datetime
import io
import json
import shlex
import sys
from pathlib import Path

RESULTS = Path(__file__).resolve().parent.parent / "docs" / "results" / "synthesis.csv"

#: The columns. ``capacity`` is ``V/E/T`` for the engine (`` no guard`` after it for a build without the
#: step guard), empty for the streaming components;
#: resources are Yosys's of the bare module (LUT4 counts a carry cell as two; ``lutram`` in
#: 16×4-bit cells); ``fmax_mhz`` is nextpnr's after routing, empty when the design was not placed,
#: and then ``critical_path`` says why; ``latency`` is the component's latency in clocks when it was
#: measured (the engine has none).
FIELDS = ("date", "target", "preset", "component", "capacity", "seed", "constraint_mhz", "fmax_mhz", "lut4",
          "ff", "dsp", "bram", "lutram", "latency", "critical_path", "command")

#: The order of the components in the file (and the tables): the pipeline's units, then the whole engine.
COMPONENT_ORDER = ("rsqrt_unit", "step_generator", "node_update", "springflat_core", "springflat_engine")

#: What makes two rows the same configuration: a newer run replaces the older row.
KEY = ("target", "preset", "component", "capacity", "seed")


def read_rows(path: Path = RESULTS) -> list[dict[str, str]]:
    """The file's rows as dicts of strings (empty string: not measured)."""
    with path.open(newline="", encoding="utf-8") as f:
        reader = csv.DictReader(f)
        if tuple(reader.fieldnames or ()) != FIELDS:
            raise ValueError(f"{path}: columns {reader.fieldnames} are not {list(FIELDS)}")
        return list(reader)


def write_rows(rows: list[dict[str, str]], path: Path = RESULTS) -> None:
    """Write ``rows`` sorted by configuration (target, preset, component, capacity, seed)."""
    def order(row):
        depths, _, guardless = row["capacity"].partition(" ")
        capacity = (*(int(v) for v in depths.split("/")), bool(guardless)) if depths else ()
        component = (COMPONENT_ORDER.index(row["component"]) if row["component"] in COMPONENT_ORDER
                     else len(COMPONENT_ORDER), row["component"])
        return row["target"], row["preset"], component, capacity, int(row["seed"] or 0)

    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=FIELDS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(sorted(rows, key=order))
    path.write_text(out.getvalue(), encoding="utf-8")


def _seed(nextpnr_command: str | None) -> str:
    """The ``--seed`` nextpnr ran with (``1``, nextpnr's default here, when the command has none)."""
    argv = shlex.split(nextpnr_command or "")
    return argv[argv.index("--seed") + 1] if "--seed" in argv else "1"


def capacity_text(capacity: dict | None) -> str:
    """The ``capacity`` column: ``V/E/T``, `` no guard`` for an engine built without the step guard, and
    `` K lanes`` for one of K > 1 lanes."""
    if not capacity:
        return ""
    text = "/".join(str(capacity[k]) for k in ("vertices", "entries", "triangles"))
    text = text if capacity.get("guard", True) else f"{text} no guard"
    return text if capacity.get("lanes", 1) == 1 else f"{text}, {capacity['lanes']} lanes"


def rows_from_report(report: dict, date: str) -> list[dict[str, str]]:
    """One row per component of a ``springflat synth --json`` report (``synth_report.json``)."""
    rows = []
    for name, c in report["components"].items():
        capacity = c.get("capacity")
        path = c.get("critical_path")
        if c.get("fmax_mhz"):
            why = path["summary"] if path else ""
        else:
            why = "not placed: " + "; ".join(c.get("does_not_fit") or ["no Fmax reported"])
        rows.append({
            "date": date, "target": report["target"], "preset": report["preset"], "component": name,
            "capacity": capacity_text(capacity),
            "seed": _seed(c.get("nextpnr_command")) if c.get("fmax_mhz") else "",
            "constraint_mhz": f"{report['freq_mhz']:g}",
            "fmax_mhz": f"{c['fmax_mhz']:.2f}" if c.get("fmax_mhz") else "",
            "lut4": str(c["luts"]), "ff": str(c["ffs"]), "dsp": str(c["dsps"]), "bram": str(c["brams"]),
            "lutram": str(c.get("lutram", "")), "latency": "" if c.get("latency") is None else str(c["latency"]),
            "critical_path": why, "command": report.get("command") or "",
        })
    return rows


def record(rows: list[dict[str, str]], new: list[dict[str, str]]) -> list[dict[str, str]]:
    """``rows`` with ``new`` added, each replacing the row of its configuration if there is one."""
    keys = {tuple(r[k] for k in KEY) for r in new}
    return [r for r in rows if tuple(r[k] for k in KEY) not in keys] + list(new)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m sim.results", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="action", required=True)
    rec = sub.add_parser("record", help="add the rows of a synth report (synth_report.json or --json output)")
    rec.add_argument("report", type=Path)
    rec.add_argument("--date", default=datetime.date.today().isoformat(), help="measurement date (default: today)")
    args = parser.parse_args(argv)
    try:
        report = json.loads(args.report.read_text(encoding="utf-8"))
        new = rows_from_report(report, args.date)
    except (OSError, ValueError, KeyError, TypeError) as e:
        print(f"sim.results: error: {args.report}: not a springflat synth report ({e})", file=sys.stderr)
        return 2
    write_rows(record(read_rows(RESULTS), new), RESULTS)
    for r in new:
        print(f"recorded {r['target']} {r['preset']} {r['component']} {r['capacity'] or '-'} seed {r['seed'] or '-'}: "
              f"{r['fmax_mhz'] or 'not placed'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
