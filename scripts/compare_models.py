#!/usr/bin/env python3
"""Compare models on the same bundles: candidate ÷ baseline relMSE at equal passes.

A quick screen before the 35-minute equal-time evaluation: renders each scene of an evaluation
config once (`infer --scene` with the first model and the config's seed, photons per pass, max
depth, schedule, emitter samples, sharp level and sampler; bundles kept under `--out`, so a
second call only reconstructs), reconstructs every bundle with each `--models` entry (`infer
--input`) and prints, per scene and overall (geometric mean, median, range, scenes better),
each later model's relMSE ÷ the first's. Equal passes, not equal time: a candidate that wins
here still has to win in `evaluate`. Writes `scores.json` under `--out/p<passes>`. Run from the
repository root, like `evaluate` (the config's scene paths are relative to it). A development
tool (numpy, OpenEXR).

    python3 scripts/compare_models.py --infer target/release/infer \
        --config configs/eval/heldout.toml --passes 64 \
        --models models/default runs/unet-direct-ft --out out/compare
"""

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tomllib

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from postfilter_probe import relmse, rgb  # noqa: E402


def load_eval_config(path, tool):
    """An evaluation config (TOML) with at least one [[scenes]]; exits naming `path` otherwise."""
    try:
        with open(path, "rb") as f:
            cfg = tomllib.load(f)
    except (OSError, tomllib.TOMLDecodeError) as e:
        sys.exit(f"{tool}: {path}: {e}")
    if not cfg.get("scenes"):
        sys.exit(f"{tool}: {path}: no [[scenes]]")
    return cfg


def geometric_mean(values):
    return math.exp(sum(math.log(max(v, 1e-30)) for v in values) / len(values))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--infer", default="target/release/infer")
    ap.add_argument("--config", default="configs/eval/heldout.toml")
    ap.add_argument("--passes", type=int, default=64)
    ap.add_argument("--models", nargs="+", required=True, help="baseline first, then candidates")
    ap.add_argument("--out", default="out/compare")
    a = ap.parse_args()
    if len(a.models) < 2:
        ap.error("--models needs a baseline and at least one candidate")
    if not os.path.isfile(a.infer):
        sys.exit(f"compare_models: {a.infer}: no such binary (build it with `cargo build --release "
                 f"-p infer`, or pass --infer $CARGO_TARGET_DIR/release/infer)")
    for model in a.models:
        if not os.path.isfile(os.path.join(model, "model.json")):
            sys.exit(f"compare_models: {model}: no model.json (not a model directory)")
    cfg = load_eval_config(a.config, "compare_models")
    # The config's renderer settings, as `evaluate` renders ours (absent: the renderer's default).
    render_flags = []
    for key in ("schedule", "emitter_samples", "sharp_level", "sampler"):
        if key in cfg:
            render_flags += ["--" + key.replace("_", "-"), str(cfg[key])]
    if "photon_focus" in cfg:
        sys.exit(f"compare_models: {a.config}: photon_focus is not passed to infer --scene")
    out = f"{a.out}/p{a.passes}"
    os.makedirs(out, exist_ok=True)
    rows = []
    for scene in cfg["scenes"]:
        name = scene["name"]
        bundle = f"{out}/{name}_bundle.exr"
        if not os.path.exists(bundle):
            subprocess.run(
                [a.infer, "--model", a.models[0], "--scene", scene["xml"],
                 "--passes", str(a.passes), "--photons", str(cfg.get("photons_per_pass", 100000)),
                 "--seed", str(cfg.get("seed", 1)), "--max-depth", str(cfg.get("max_depth", 10)),
                 *render_flags, "--output", f"{out}/{name}.exr"],
                check=True, stdout=subprocess.DEVNULL,
            )
        ref = rgb(scene["reference"])
        row = {"scene": name}
        for i, model in enumerate(a.models):
            recon = f"{out}/{name}_m{i}.exr"
            subprocess.run([a.infer, "--model", model, "--input", bundle, "--output", recon],
                           check=True, stdout=subprocess.DEVNULL)
            row[model] = relmse(rgb(recon), ref)
        rows.append(row)
        ratios = " ".join(f"{row[m] / row[a.models[0]]:.3f}" for m in a.models[1:])
        print(f"{name} {ratios}", flush=True)
    with open(f"{out}/scores.json", "w") as f:
        json.dump(rows, f, indent=1)
    for model in a.models[1:]:
        x = [r[model] / r[a.models[0]] for r in rows]
        gm = geometric_mean(x)
        print(f"{model} ÷ {a.models[0]}: geometric mean {gm:.4f}, median "
              f"{statistics.median(x):.4f}, range {min(x):.3f}–{max(x):.3f}, better on "
              f"{sum(v < 1 for v in x)} of {len(x)}")


if __name__ == "__main__":
    try:
        main()
    except subprocess.CalledProcessError as e:
        # infer has printed its own error (file, channel or line) on stderr.
        sys.exit(f"compare_models: {e.cmd[0]} failed with exit status {e.returncode}")
