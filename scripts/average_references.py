#!/usr/bin/env python3
"""Averaged references for one split of a `datagen` dataset, with their own error measured.

A dataset's reference is one long multi-level SPPM run (level `y`, `reference_passes` ×
`reference_photons_per_pass`, seed `reference_seed`). It still carries noise, and relMSE against
it adds that noise to every method's error alike, pulling every ratio towards 1. This script
renders RUNS − 1 more runs of exactly the same settings with other seeds (the first run is the
dataset's own reference file), and writes for every scene of the split:

* `<out>/<id>.exr` — the per-pixel mean of the RUNS runs (RGB, float32);
* `<out>/noise.json` — per scene the estimated relMSE of one run and of the mean against the
  noise-free limit of the same estimator: Σ_p s²_p / (ref_p² + 0.01) / (3·pixels) with s² the
  unbiased sample variance across runs (÷ RUNS for the mean). It measures variance only; the
  estimator's bias at `reference_passes` (level y: the smallest radius) is not included.

`evaluate` uses the directory with `references = "<out name>"` in the `[dataset]` table of its
config (configs/eval/small-avg.toml uses `--runs 8 --out references-avg8`). The extra runs are kept in `<dataset>/reference-runs/`
and reused, so the script can be killed and restarted, or re-run with more runs. Needs numpy and the `OpenEXR` Python module (dev tools only).

Usage: scripts/average_references.py [--dataset data/small] [--split test] [--runs 8]
                                     [--out references-avg8] [--render target/release/render]
"""

import argparse
import json
import os
import subprocess
import sys

import numpy as np
import OpenEXR


def read_rgb(path, layer=None):
    """RGB of an EXR (a layer `layer.R/G/B` of a bundle, or plain R, G, B) as float64 HxWx3."""
    channels = {}
    for part in OpenEXR.File(str(path)).parts:
        channels.update(part.channels)
    names = [f"{layer}.{c}" if layer else c for c in "RGB"]
    if all(n in channels for n in names):
        return np.stack([np.asarray(channels[n].pixels) for n in names], -1).astype(np.float64)
    # The module groups R, G, B of a layer into one channel named after the layer.
    key = layer if layer else "RGB"
    if key in channels and np.asarray(channels[key].pixels).ndim == 3:
        return np.asarray(channels[key].pixels).astype(np.float64)
    sys.exit(f"{path}: no {'layer ' + layer if layer else 'RGB'} channels (has {sorted(channels)[:8]}…)")


def write_rgb(path, rgb):
    """Writes float32 RGB atomically (temp file + rename)."""
    tmp = f"{path}.tmp.exr"
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    channels = {c: np.ascontiguousarray(rgb[..., i].astype(np.float32)) for i, c in enumerate("RGB")}
    with OpenEXR.File(header, channels) as f:
        f.write(tmp)
    os.replace(tmp, path)


def relmse_weights(ref):
    """SPEC §4 relMSE denominator per pixel: (mean over RGB of the reference)² + 0.01."""
    return 1.0 / (ref.mean(-1, keepdims=True) ** 2 + 0.01)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--dataset", default="data/small")
    ap.add_argument("--split", default="test")
    ap.add_argument("--runs", type=int, default=8, help="runs per scene, the dataset's own included")
    ap.add_argument("--out", default="references-avg8", help="directory inside the dataset")
    ap.add_argument("--render", default="target/release/render")
    ap.add_argument("--threads", type=int, default=0)
    args = ap.parse_args()
    if args.runs < 2:
        sys.exit("--runs must be at least 2 (the spread between runs is the noise estimate)")
    manifest = json.load(open(os.path.join(args.dataset, "manifest.json")))
    render_cfg = manifest["config"]["render"]
    out_dir = os.path.join(args.dataset, args.out)
    # Runs are kept apart from any one average, so a larger --runs reuses them.
    runs_dir = os.path.join(args.dataset, "reference-runs")
    os.makedirs(runs_dir, exist_ok=True)
    os.makedirs(out_dir, exist_ok=True)
    scenes = [s for s in manifest["scenes"] if s["split"] == args.split]
    if not scenes:
        sys.exit(f"{args.dataset}/manifest.json: no scene in split {args.split!r}")
    noise = {}
    for s in scenes:
        images = [read_rgb(os.path.join(args.dataset, s["reference"]))]
        for r in range(1, args.runs):
            # Seeds far from the dataset's (reference seeds are 32-bit hashes; sample seeds small).
            seed = (s["reference_seed"] + 7919 * r) % 2**32
            prefix = os.path.join(runs_dir, f"{s['id']}_run{r}")
            bundle = f"{prefix}_p{s['reference_passes']:04d}.exr"
            if not os.path.exists(bundle):
                cmd = [args.render, os.path.join(args.dataset, s["xml"]),
                       "--integrator", "sppm-ml",
                       "--photons", str(s["reference_photons"]),
                       "--passes", str(s["reference_passes"]),
                       "--max-depth", str(render_cfg["max_depth"]),
                       "--seed", str(seed), "--threads", str(args.threads),
                       "--out", prefix]
                print(" ".join(cmd), flush=True)
                subprocess.run(cmd, check=True)
            images.append(read_rgb(bundle, manifest.get("reference_level", "y")))
        stack = np.stack(images)
        mean = stack.mean(0)
        var = stack.var(0, ddof=1)
        w = relmse_weights(mean)
        one_run = float((var * w).mean())
        noise[s["id"]] = {
            "runs": args.runs,
            "relmse_one_run": one_run,
            "relmse_mean": one_run / args.runs,
            "seeds": [s["reference_seed"]] + [(s["reference_seed"] + 7919 * r) % 2**32
                                              for r in range(1, args.runs)],
        }
        write_rgb(os.path.join(out_dir, f"{s['id']}.exr"), mean)
        print(f"{s['id']}: one run ≈ {one_run:.3e} relMSE of noise, mean of {args.runs} ≈ "
              f"{one_run / args.runs:.3e}", flush=True)
    tmp = os.path.join(out_dir, "noise.json.tmp")
    with open(tmp, "w") as f:
        json.dump({"dataset": args.dataset, "split": args.split,
                   "reference_passes": scenes[0]["reference_passes"],
                   "reference_photons": scenes[0]["reference_photons"],
                   "scenes": noise}, f, indent=2)
    os.replace(tmp, os.path.join(out_dir, "noise.json"))


if __name__ == "__main__":
    main()
