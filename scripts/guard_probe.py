#!/usr/bin/env python3
"""Probe: the guard's κ and λ (docs/method.md §5.4) at equal passes on training scenes.

For each scene this renders a bundle at the evaluation's setting (`infer --scene`: 100 000
photons per pass, `--passes`, max depth 10, seed 7; skipped when present), reconstructs it with
`--model` at every `κ,λ` pair given (`infer --guard κ --guard-target-noise λ`), and prints each
pair's relMSE ÷ the first pair's per scene, then the geometric mean, median, worst and how many
scenes it improves. Choose on training scenes (their references may be noisy: that noise adds to
every pair alike and pulls the ratios toward 1), never on the frozen held-out ones. A development
tool (numpy, OpenEXR).

    python3 scripts/guard_probe.py --infer target/release/infer --passes 256 \\
        --dataset data/large \\
        --out out/guard-probe-256 \\
        --pairs 16,8 16,32 8,32
"""

import math
import os
import statistics
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from postfilter_probe import probe_render, probe_scenes, relmse, rgb, scene_probe_arguments  # noqa: E402


def main():
    ap = scene_probe_arguments(__doc__, "out/guard-probe")
    ap.add_argument("--pairs", nargs="+", default=["16,8", "16,32"],
                    help="κ,λ pairs; the first is the baseline")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    errors = {}
    for scene in probe_scenes(a):
        name = os.path.basename(os.path.normpath(scene))
        _, bundle = probe_render(a.infer, a.model, scene, a.passes, a.out)
        ref = rgb(a.references.format(name=name))
        row = []
        for pair in a.pairs:
            kappa, lam = pair.split(",")
            out = f"{a.out}/{name}_k{kappa}_l{lam}.exr"
            if not os.path.exists(out):
                subprocess.run(
                    [a.infer, "--model", a.model, "--input", bundle, "--output", out,
                     "--guard", kappa, "--guard-target-noise", lam],
                    check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                )
            row.append(relmse(rgb(out), ref))
        errors[name] = row
    print("scene", *a.pairs)
    for name, row in errors.items():
        print(name, *[f"{e / row[0]:.4f}" for e in row])
    for i, pair in enumerate(a.pairs):
        r = [row[i] / row[0] for row in errors.values()]
        gmean = math.exp(sum(map(math.log, r)) / len(r))
        print(f"{pair}: geometric mean {gmean:.4f}, median {statistics.median(r):.4f}, "
              f"worst {max(r):.3f}, better on {sum(x < 1 for x in r)} of {len(r)}")


if __name__ == "__main__":
    main()
