"""The row of docs/fixed-point.md's property-test table, from a run's ``SPRINGFLAT_PROPERTY_LOG``.

    SPRINGFLAT_PROPERTY_EXAMPLES=5000 SPRINGFLAT_PROPERTY_LOG=runs.jsonl \\
        .venv/bin/python -m pytest tests/golden_model/test_formats_property.py
    .venv/bin/python benchmarks/property_summary.py runs.jsonl --name "longer (5,000)"

Counts every outcome the test logs (``invalid``: refused by ``FormatSet``; ``refused``: by the host;
``saturated``; ``ran``: no saturation, deviation within the bound; ``stalled``: the guarded run found
no step that lowers the fixed-point energy) and, over the runs without saturation, the worst
deviation from float over the bound per rounding and the worst deviation.
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from pathlib import Path

OUTCOMES = ("invalid", "refused", "saturated", "ran", "stalled")
ROUNDINGS = ("half_up", "nearest_even", "floor")


def summarise(records: list[dict]) -> dict:
    """Counts per outcome, and the worst ``deviation / bound`` per rounding and ``deviation`` over ``ran``."""
    counts = Counter(r["outcome"] for r in records)
    unknown = set(counts) - set(OUTCOMES)
    if unknown:
        raise SystemExit(f"property_summary: unknown outcomes {sorted(unknown)}")
    ran = [r for r in records if r["outcome"] == "ran"]
    worst_ratio = {rounding: max((r["deviation"] / r["bound"] for r in ran if r["rounding"] == rounding),
                                 default=0.0) for rounding in ROUNDINGS}
    return {"examples": len(records), **{o: counts.get(o, 0) for o in OUTCOMES}, "worst_ratio": worst_ratio,
            "worst_deviation": max((r["deviation"] for r in ran), default=0.0)}


def markdown_row(name: str, s: dict) -> str:
    ratios = ", ".join(f"{s['worst_ratio'][r]:.3f}" for r in ROUNDINGS)
    return (f"| {name} | {s['examples']:,} | {s['invalid']:,} | {s['refused']:,} | {s['saturated']:,} | "
            f"{s['ran']:,} | {s['stalled']:,} | {ratios} | {s['worst_deviation']:.3f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("log", type=Path, help="the JSON-lines file SPRINGFLAT_PROPERTY_LOG named")
    parser.add_argument("--name", default="run", help="the row's first cell")
    args = parser.parse_args()
    records = [json.loads(line) for line in args.log.read_text(encoding="utf-8").splitlines() if line.strip()]
    print(markdown_row(args.name, summarise(records)))


if __name__ == "__main__":
    main()
