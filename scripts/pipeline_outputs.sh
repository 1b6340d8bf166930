#!/usr/bin/env bash
# Runs the pipeline's commands on small inputs with the binaries in BIN and writes every output
# into OUT, with OUT.sha256 listing them: run it with the binaries of two commits into the same
# OUT path (paths are recorded in some outputs), moving the first OUT away in between, and diff
# the two lists to see what a change altered. Outputs that record wall-clock times differ
# between any two runs (data/*/timings, eval/, run/metrics.*, run/checkpoint/state.json, the
# `seconds` of a bundle's metadata and what bundle_info prints of it); everything else must be
# byte-identical.
#   scripts/pipeline_outputs.sh target/release /tmp/outputs
set -euo pipefail
BIN=$(realpath "$1"); OUT=$2
cd "$(dirname "$0")/.."
rm -rf "$OUT"; mkdir -p "$OUT"
run() { "$@" >/dev/null 2>&1 || { echo "failed: $*" >&2; exit 1; }; }
run "$BIN/render" scenes/default/scene.xml --integrator sppm-ml --passes 2,4 --photons 20000 --seed 3 --threads 2 --out "$OUT/render/b"
run "$BIN/render" scenes/default/scene.xml --integrator sppm --passes 4 --photons 20000 --seed 3 --threads 2 --out "$OUT/render/s"
run "$BIN/render" scenes/default/scene.xml --integrator path --spp 4 --seed 3 --threads 2 --out "$OUT/render/path.exr" --png "$OUT/render/path.png"
"$BIN/bundle_info" "$OUT/render/b_p0004.exr" --png "$OUT/render/preview" >"$OUT/render/bundle_info.txt" 2>/dev/null
run "$BIN/infer" --scene scenes/default/scene.xml --passes 4 --photons 20000 --seed 2 --threads 2 --png --output "$OUT/infer/ours.exr"
run "$BIN/infer" --input "$OUT/render/b_p0004.exr" --output "$OUT/infer2/ours.exr" --png
run "$BIN/datagen" scenes --config configs/datagen/tiny.toml --out "$OUT/data/tiny"
run "$BIN/datagen" render --quiet --config configs/datagen/tiny.toml --out "$OUT/data/tiny"
"$BIN/datagen" check "$OUT/data/tiny" >"$OUT/datagen_check.txt" 2>&1
cat >"$OUT/train.toml" <<T
backend = "flex"
dataset = "$OUT/data/tiny"
preset = "tiny"
patch = 16
stride = 16
batch = 4
epochs = 2
lr = 1e-4
seed = 1
output = "$OUT/run"
T
run "$BIN/train" --config "$OUT/train.toml"
cat >"$OUT/eval.toml" <<T
model = "models/default"
output = "$OUT/eval"
photons_per_pass = 2000
passes = [2, 4]
seed = 1
tile = 128
threads = 2
backend = "flex"
max_depth = 8

[dataset]
dir = "$OUT/data/tiny"
split = "test"
limit = 1
T
run "$BIN/evaluate" --config "$OUT/eval.toml"
(cd "$OUT" && find . -type f | sort | xargs sha256sum) >"$OUT.sha256"
echo "$(wc -l <"$OUT.sha256") files listed in $OUT.sha256"
