#!/usr/bin/env bash
# Consistency in practice (issue 6, "Must show 2"): on a scene the network never saw, the
# reconstruction's relMSE must fall as passes grow, as the input levels' do.
#
#   scripts/consistency.sh [MODEL_DIR] [SCENE_XML] [PHOTONS] [PASSES]
#   defaults: models/default scenes/validation/cornell-diffuse/scene.xml 16000 100,400,1600
#
# Reference: our path tracer (validated against Mitsuba 3, docs/validation.md) at 8192 spp with
# max_depth 24 (deeper than SPPM's 16 photon bounces, so both see the same light). Writes
# out/consistency/<scene>/ and prints a markdown table (relMSE vs the reference).
#
# Environment (all optional): NO_BUILD=1 skips `cargo build`; RENDER / INFER name the binaries
# (default: ${CARGO_TARGET_DIR:-target}/release/{render,infer}); OUT_ROOT replaces
# out/consistency; REF_SPP (default 8192) sets the reference's spp; THREADS is passed to
# render and infer as --threads (default 0: all cores); REFERENCE names a reference EXR to use
# instead of rendering one (e.g. the external scenes' own); MAX_DEPTH is passed to the SPPM
# render as --max-depth (default: render's). Existing files are reused.
set -euo pipefail
cd "$(dirname "$0")/.."
MODEL=${1:-models/default}
SCENE=${2:-scenes/validation/cornell-diffuse/scene.xml}
PHOTONS=${3:-16000}
PASSES=${4:-100,400,1600}
NAME=$(basename "$(dirname "$SCENE")")
OUT=${OUT_ROOT:-out/consistency}/$NAME
mkdir -p "$OUT"
[ -n "${NO_BUILD:-}" ] || cargo build --release -p renderer -p infer --bins --locked
BIN=${CARGO_TARGET_DIR:-target}/release
RENDER=${RENDER:-$BIN/render}
INFER=${INFER:-$BIN/infer}
THREADS=${THREADS:-0}
[ -z "${REFERENCE:-}" ] || [ -f "$OUT/reference.exr" ] || cp "$REFERENCE" "$OUT/reference.exr"
[ -f "$OUT/reference.exr" ] || "$RENDER" "$SCENE" --integrator path --spp "${REF_SPP:-8192}" --max-depth 24 \
    --seed 7 --threads "$THREADS" --out "$OUT/reference.exr" --png "$OUT/reference.png"
LAST=$(printf 'p%04d' "${PASSES##*,}")
[ -f "$OUT/bundle_$LAST.exr" ] || "$RENDER" "$SCENE" --integrator sppm-ml --photons "$PHOTONS" \
    --passes "$PASSES" --seed 3 --threads "$THREADS" ${MAX_DEPTH:+--max-depth "$MAX_DEPTH"} \
    --out "$OUT/bundle"
echo "| passes | y | z1 | z2 | z3 | z4 | ours | ours / best input |"
echo "|---:|---:|---:|---:|---:|---:|---:|---:|"
for p in ${PASSES//,/ }; do
    tag=$(printf 'p%04d' "$p")
    "$INFER" --model "$MODEL" --input "$OUT/bundle_$tag.exr" --reference "$OUT/reference.exr" \
        --threads "$THREADS" --output "$OUT/ours_$tag.exr" --png > /dev/null
    python3 - "$OUT/ours_${tag}_report.json" "$p" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
cells = " | ".join(f"{v:.3e}" for v in r["levels"])
print(f"| {sys.argv[2]} | {cells} | {r['output']:.3e} | {r['ratio_to_best']:.2f} |")
PY
done
