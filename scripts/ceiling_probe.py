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
import os
import statistics
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from compare_models import geometric_mean, load_eval_config  # noqa: E402
from postfilter_probe import oidn, oracle, read, relmse, rgb  # noqa: E402

LEVELS = ("y", "z1", "z2", "z3", "z4")


def summary(values):
    return f"median {statistics.median(values):.3f}, geometric mean {geometric_mean(values):.3f}"


def equal_time_pairs(results, passes):
    """(ours, standard SPPM at equal time, reference noise) relMSE per scene at `passes`."""
    noise = {s["name"]: s.get("reference_noise") or 0.0 for s in results["config"]["scenes"]}
    pairs = [
        (c["ours_relmse"], c["standard_equal_time"]["relmse"], noise.get(scene["name"], 0.0))
        for scene in results["scenes"]
        for c in scene["eval"]["checkpoints"]
        if c["passes"] == passes and c.get("standard_equal_time")
    ]
    if not pairs:
        sys.exit(f"ceiling_probe: no checkpoint at {passes} passes in --results")
    return pairs


def median_ratio(pairs, m):
    """The median of ours ÷ standard SPPM with our error above the reference's noise × m."""
    return statistics.median((m * (a - n) + n) / b for a, b, n in pairs)


def needed_factor(pairs, target):
    """The factor m in [0, 1] at which `median_ratio` falls to `target` (bisection; it rises
    with m), or None if even m = 0 stays above it. Call it where m = 1 is above `target`."""
    if median_ratio(pairs, 0.0) > target:
        return None
    lo, hi = 0.0, 1.0
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if median_ratio(pairs, mid) <= target else (lo, mid)
    return lo


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
    cfg = load_eval_config(a.config, "ceiling_probe")
    folder = f"{a.compare}/p{a.passes}"
    rows = []
    for scene in cfg["scenes"]:
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
    for key in ("oidn", "oracle8", "oracle4"):
        print(f"{key} ÷ ours ({len(rows)} scenes): {summary([r[key] for r in rows])}")
    if a.results:
        try:
            with open(a.results) as f:
                results = json.load(f)
        except (OSError, json.JSONDecodeError) as e:
            sys.exit(f"ceiling_probe: {a.results}: {e}")
        pairs = equal_time_pairs(results, a.passes)
        now = median_ratio(pairs, 1.0)
        head = f"median ours ÷ standard SPPM at {a.passes} passes: {now:.3f}"
        if now <= a.target:
            print(f"{head}, at or below {a.target} already")
        elif (m := needed_factor(pairs, a.target)) is None:
            print(f"{head}; even an error of zero above the references' noise does not bring "
                  f"it to {a.target}")
        else:
            print(f"{head}; it reaches {a.target} when our error (above the references' noise) "
                  f"is × {m:.3f} on every scene")


if __name__ == "__main__":
    main()
