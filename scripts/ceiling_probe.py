#!/usr/bin/env python3
"""Probe: how much of our error could any reconstruction of the same bundles still remove?

Reads the bundles and reconstructions that `scripts/compare_models.py` left under
`--compare/p<passes>` (`<scene>_bundle.exr`, `<scene>_m<K>.exr`: model K of its `--models`) for
the scenes of an evaluation config, and prints per scene and overall, as relMSE ÷ the
reconstruction's own, against the config's references:

- `oidn`: OIDN 2.5 (HDR, albedo + normal from the bundle; the SPPM + OIDN peer's denoiser)
  applied to the reconstruction — the ceiling of any filter of the output;
- `oracle8`, `oracle4`: in every 8×8 (4×4) block, whichever of the reconstruction and the five
  input levels has the least error against the reference — the ceiling of a better choice of
  level (optimistic: it also picks up the reference's own noise).

With `--results` (an `evaluate` results.json of the same config) it also prints what the
reconstruction's error would have to be multiplied by, on every scene, for the median ratio to
standard SPPM at equal time to reach `--target` (the reference's noise held fixed: only our
error shrinks). Equal passes; a development tool (numpy, OpenEXR, pyoidn), run from the
repository root.

    python3 scripts/compare_models.py --config configs/eval/heldout.toml --passes 256 \
        --models models/default models/default --out out/compare
    python3 scripts/ceiling_probe.py --config configs/eval/heldout.toml --compare out/compare \
        --passes 256 --results out/eval/heldout/results.json
"""

import argparse
import json
import math
import os
import statistics
import sys
import tomllib

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from postfilter_probe import oidn, oracle, read, relmse, rgb  # noqa: E402

LEVELS = ("y", "z1", "z2", "z3", "z4")


def summary(values):
    gm = math.exp(sum(math.log(max(v, 1e-30)) for v in values) / len(values))
    return f"median {statistics.median(values):.3f}, geometric mean {gm:.3f}"


def needed_factor(results, passes, target):
    """The factor m on (ours − reference noise) at which the median of ours ÷ standard SPPM at
    equal time over the scenes of `results` reaches `target` (bisection; None if even m = 0
    does not)."""
    noise = {s["name"]: s.get("reference_noise") or 0.0 for s in results["config"]["scenes"]}
    pairs = []
    for scene in results["scenes"]:
        for c in scene["eval"]["checkpoints"]:
            if c["passes"] == passes and c.get("standard_equal_time"):
                pairs.append((c["ours_relmse"], c["standard_equal_time"]["relmse"],
                              noise.get(scene["name"], 0.0)))
    if not pairs:
        sys.exit(f"ceiling_probe: no checkpoint at {passes} passes in --results")

    def median(m):
        return statistics.median((m * (a - n) + n) / b for a, b, n in pairs)

    if median(0.0) > target:
        return None, median(1.0)
    lo, hi = 0.0, 1.0
    if median(hi) <= target:
        return 1.0, median(1.0)
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if median(mid) <= target else (lo, mid)
    return lo, median(1.0)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", default="configs/eval/heldout.toml")
    ap.add_argument("--compare", default="out/compare", help="compare_models.py's --out")
    ap.add_argument("--passes", type=int, default=256)
    ap.add_argument("--model-index", type=int, default=0,
                    help="which of compare_models' --models (its _m<K>.exr) to probe")
    ap.add_argument("--results", help="evaluate's results.json of the same config")
    ap.add_argument("--target", type=float, default=0.35)
    a = ap.parse_args()
    try:
        with open(a.config, "rb") as f:
            cfg = tomllib.load(f)
    except (OSError, tomllib.TOMLDecodeError) as e:
        sys.exit(f"ceiling_probe: {a.config}: {e}")
    folder = f"{a.compare}/p{a.passes}"
    rows = []
    for scene in cfg.get("scenes", []):
        name = scene["name"]
        bundle, recon = f"{folder}/{name}_bundle.exr", f"{folder}/{name}_m{a.model_index}.exr"
        for path in (bundle, recon):
            if not os.path.exists(path):
                sys.exit(f"ceiling_probe: {path}: missing (run scripts/compare_models.py with "
                         f"--config {a.config} --passes {a.passes} --out {a.compare} first)")
        ref = rgb(scene["reference"])
        ours = rgb(recon)
        albedo = rgb(bundle, "albedo.")
        normal = read(bundle, ["normal.X", "normal.Y", "normal.Z"])
        levels = [rgb(bundle, level + ".") for level in LEVELS]
        error = relmse(ours, ref)
        row = {
            "scene": name,
            "oidn": relmse(oidn(ours, albedo, normal), ref) / error,
            "oracle8": relmse(oracle([ours] + levels, ref, 8), ref) / error,
            "oracle4": relmse(oracle([ours] + levels, ref, 4), ref) / error,
        }
        rows.append(row)
        print(f"{name}: oidn {row['oidn']:.3f}, oracle8 {row['oracle8']:.3f}, "
              f"oracle4 {row['oracle4']:.3f}", flush=True)
    if not rows:
        sys.exit(f"ceiling_probe: {a.config}: no [[scenes]]")
    for key in ("oidn", "oracle8", "oracle4"):
        print(f"{key} ÷ ours ({len(rows)} scenes): {summary([r[key] for r in rows])}")
    if a.results:
        try:
            results = json.load(open(a.results))
        except (OSError, json.JSONDecodeError) as e:
            sys.exit(f"ceiling_probe: {a.results}: {e}")
        m, now = needed_factor(results, a.passes, a.target)
        if now <= a.target:
            print(f"median ours ÷ standard SPPM at {a.passes} passes: {now:.3f}, at or below "
                  f"{a.target} already")
        elif m is None:
            print(f"median ours ÷ standard SPPM at {a.passes} passes: {now:.3f}; even an error of "
                  f"zero above the references' noise does not bring it to {a.target}")
        else:
            print(f"median ours ÷ standard SPPM at {a.passes} passes: {now:.3f}; it reaches "
                  f"{a.target} when our error (above the references' noise) is × {m:.3f} on "
                  f"every scene")


if __name__ == "__main__":
    main()
