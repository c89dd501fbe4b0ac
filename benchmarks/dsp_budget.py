"""The ECP5-85F's multipliers against what the engine's datapaths take: what the guard and a second lane cost.

Usage::

    .venv/bin/python benchmarks/dsp_budget.py

Elaborates ``SpringflatEngine`` at ``DEFAULT_CAPACITY`` with and without the step guard, and each unit,
for ECP5 (``MULT18X18D`` instances, as ``synth`` maps them), for each preset, and counts the multipliers.
A second lane (``lanes = 2`` of issue 29) is another force pass, area unit and integrator, and with the
guard another certificate too (each lane certifies its share of the triangles). The certificate runs
at II 2 in the engine; the column for II 1 is the guarded engine with the certificate at II 1.
docs/synthesis.md quotes the table.
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from golden_model.engine_spec.image import DEFAULT_CAPACITY  # noqa: E402
from golden_model.fixed import FormatSet  # noqa: E402
from hdl import AreaError, ForcePass, GuardCertificate, Integrator  # noqa: E402
from hdl.dsp import mult18x18d_count as mult18x18d  # noqa: E402
from hdl.engine import SpringflatEngine  # noqa: E402
from sim.synth import TARGETS  # noqa: E402

#: MULT18X18D blocks of the LFE5U-85F.
ECP5_85F_DSP = TARGETS["ecp5"].capacity["dsps"]
PRESETS = ("default", "narrow")


def main() -> None:
    print("| preset | engine without the guard | certificate (II 2) | engine (with the guard) | force pass | "
          "area unit | integrator | two lanes, without the guard | two lanes, with the guard | "
          "the guard's certificate at II 1 | 85F |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for preset in PRESETS:
        fs = FormatSet.preset(preset)
        bare = mult18x18d(SpringflatEngine(fs, replace(DEFAULT_CAPACITY, guard=False)))
        guarded = mult18x18d(SpringflatEngine(fs, DEFAULT_CAPACITY))
        force = mult18x18d(ForcePass(fs, energy=True, saturations=True))
        area = mult18x18d(AreaError(fs))
        integrator = mult18x18d(Integrator(fs, saturations=True))
        cert1, cert2 = mult18x18d(GuardCertificate(fs)), mult18x18d(GuardCertificate(fs, interval=2))
        if guarded - bare != cert2:
            raise SystemExit(f"{preset}: the guard adds {guarded - bare} multipliers, its certificate has {cert2}")
        lane = force + area + integrator

        def fits(n: int) -> str:
            return f"{n}" if n <= ECP5_85F_DSP else f"**{n}: does not fit**"

        print(f"| {preset} | {bare} | {cert2} | {fits(guarded)} | {force} | {area} | {integrator} | "
              f"{fits(bare + lane)} | {fits(guarded + lane + cert2)} | {fits(guarded - cert2 + cert1)} | "
              f"{ECP5_85F_DSP} |")


if __name__ == "__main__":
    main()
