#!/usr/bin/env python3
"""Probe: how much of the output's error is the photon-free part, and which direct filter.

The emission split (docs/method.md §5.4) adds the fused photon-free part of eye subpaths A and
B — emission and next-event estimation — after Eq. 6, unfiltered. For each scene this probe
renders a bundle at the evaluation's setting (`infer --scene`: 100 000 photons per pass,
`--passes`, max depth 10) and reconstructs it with `--model` (its own `direct_filter`, if any,
taken out), then reports:

- `direct_share`: the fused part's own noise (its variance, from `directvariance`) as a share
  of the output's relMSE — what no choice of Eq. 6's weights can remove;
- `ab_check`: the measured mean (A − B)² over the predicted v_A + v_B (≈ 1: the variances are
  right);
- `{mode}-s{σ₀}k{k}`: the output's relMSE with the fused part replaced by the cross-bilateral of
  model/src/screen_filter.rs (G-buffer guides, σ₀ at 64 passes, range strength k), its range
  term reading v_c + v_n (`sum`), 2·min(v_c, v_n) (`min`) or 2·v_c (`centre`), ÷ the output's
  (`--sigmas`, `--ks`, `--modes` choose the grid; σ is the bandwidth at `--passes`).

`--dataset DIR` takes the first `--per-family` (3) training scenes of each family from DIR's
manifest (or `--scenes` directories with a `--references` pattern, `{name}` the directory's
name; a scene a manifest puts in another split is refused). Choose on training scenes (their
references may be noisy: that noise is independent and adds to every variant alike), never on
the frozen held-out ones. Equal passes; a development tool (numpy, OpenEXR).

    python3 scripts/direct_filter_probe.py --infer target/release/infer --model models/default \
        --dataset data/large \
        --out out/direct-filter-probe
"""

import json
import math
import os
import statistics
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from postfilter_probe import (  # noqa: E402
    bilateral, fused_direct, probe_render, probe_scenes, read, relmse, rgb,
    scene_probe_arguments,
    unfiltered_model,
)


def main():
    ap = scene_probe_arguments(__doc__, "out/direct-filter-probe")
    ap.add_argument("--sigmas", default="1,2,3",
                    help="bandwidths in pixels at --passes (the shipped σ₀ = 1 is 0.794 at 256)")
    ap.add_argument("--ks", default="1,2,4", help="range strengths")
    ap.add_argument("--modes", default="sum,min,centre", help="range noise rules")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    model = unfiltered_model(a.model, a.out)
    rows = []
    for scene in probe_scenes(a):
        name = os.path.basename(os.path.normpath(scene))
        out_path, bundle = probe_render(a.infer, model, scene, a.passes, a.out)
        ref = rgb(a.references.format(name=name))
        out = rgb(out_path)
        ya, zb = rgb(bundle, "ydirect."), rgb(bundle, "zdirect.")
        dv = read(bundle, ["directvariance.y", "directvariance.z"])
        va, vb = dv[..., 0], dv[..., 1]
        fused, fused_var = fused_direct(bundle)
        albedo = rgb(bundle, "albedo.")
        normal = read(bundle, ["normal.X", "normal.Y", "normal.Z"])
        depth = read(bundle, ["depth.Z"])[..., 0]
        norm = ref.mean(-1) ** 2 + 0.01
        error = relmse(out, ref)
        row = {
            "scene": name,
            "out": error,
            "direct_share": float((fused_var / norm).mean()) / error,
            "ab_check": float((((ya - zb) ** 2).mean(-1) / norm).mean())
            / max(float(((va + vb) / norm).mean()), 1e-30),
        }
        for mode in a.modes.split(","):
            for sigma in [float(x) for x in a.sigmas.split(",")]:
                for k in [float(x) for x in a.ks.split(",")]:
                    f = bilateral(fused, fused_var, albedo, normal, depth, sigma, k, noise=mode)
                    row[f"{mode}-s{sigma:g}k{k:g}"] = relmse(out - fused + f, ref) / error
        rows.append(row)
        print(json.dumps({k: round(v, 3) if isinstance(v, float) else v for k, v in row.items()}),
              flush=True)
    with open(f"{a.out}/rows.json", "w") as f:
        json.dump(rows, f, indent=1)
    print("\n| variant | median | geometric mean | worst |\n|---|---|---|---|")
    for k in [k for k in rows[0] if k not in ("scene", "out")]:
        x = [r[k] for r in rows]
        gm = math.exp(sum(math.log(max(v, 1e-30)) for v in x) / len(x))
        print(f"| {k} | {statistics.median(x):.3f} | {gm:.3f} | {max(x):.3f} |")


if __name__ == "__main__":
    main()
