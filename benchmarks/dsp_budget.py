"""The ECP5-85F's multipliers against what the engine's datapaths take: what a second lane or the guard costs.

Usage::

    .venv/bin/python benchmarks/dsp_budget.py

Elaborates each unit of ``SpringflatEngine`` for ECP5 (``MULT18X18D`` instances, as ``synth`` maps
them) for each preset and counts its multipliers, then adds them up for the engine as it is, for a
second lane (another force pass, area unit and integrator: ``lanes = 2`` of issue 29) and for the
step guard's certificate at II 1 and II 2, against the LFE5U-85F's 156. docs/synthesis.md quotes the table.
"""

from __future__ import annotations

import sys
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
    print("| preset | engine | force pass | area unit | integrator | the rest | one lane more | "
          "engine + certificate II 1 | engine + certificate II 2 | 85F |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for preset in PRESETS:
        fs = FormatSet.preset(preset)
        engine = mult18x18d(SpringflatEngine(fs, DEFAULT_CAPACITY))
        force = mult18x18d(ForcePass(fs, energy=True, saturations=True))
        area = mult18x18d(AreaError(fs))
        integrator = mult18x18d(Integrator(fs, saturations=True))
        lane = force + area + integrator
        cert1, cert2 = mult18x18d(GuardCertificate(fs)), mult18x18d(GuardCertificate(fs, interval=2))

        def fits(n: int) -> str:
            return f"{n}" if n <= ECP5_85F_DSP else f"**{n}: does not fit**"

        print(f"| {preset} | {engine} | {force} | {area} | {integrator} | {engine - lane} | {fits(engine + lane)} | "
              f"{fits(engine + cert1)} | {fits(engine + cert2)} | {ECP5_85F_DSP} |")


if __name__ == "__main__":
    main()
