#!/usr/bin/env bash
# The robustness table of docs/results.md ("Never worse than its inputs"): the external scenes
# at 64 and 256 passes x 100 000 photons, seeds 1-20 each, every bundle reconstructed with the
# given weights; per scene and pass count the output's relMSE over the best input level's,
# max and median, and the seeds above 1.05.
#
#   scripts/robustness_table.sh BIN_DIR MODEL_DIR OUT_DIR [SEEDS]
#
# BIN_DIR holds release binaries (`render`, `infer`; e.g. target/release). Rendering (about
# 80 s per seed and scene on 2 cores) is skipped for bundles already in OUT_DIR, so a stopped
# run continues where it was and a second model is measured on the same bundles. SEEDS defaults
# to "$(seq 1 20)". Scenes from ../shared/scenes/external (or $SPPM_EXTERNAL_SCENES).
set -euo pipefail
bin="$1"; model="$2"; out="$3"; seeds="${4:-$(seq 1 20)}"
scenes="${SPPM_EXTERNAL_SCENES:-$(dirname "$0")/../../shared/scenes/external}"
mkdir -p "$out/bundles" "$out/$(basename "$model")"
for scene in cbox veach-mis water-caustic; do
    for seed in $seeds; do
        prefix="$out/bundles/${scene}_s$(printf %02d "$seed")"
        if [ ! -f "${prefix}_p0256.exr" ]; then
            "$bin/render" "$scenes/$scene/scene.xml" --integrator sppm-ml --photons 100000 \
                --passes 64,256 --seed "$seed" --max-depth 12 --out "$prefix" 2>/dev/null
        fi
        for passes in 0064 0256; do
            report="$out/$(basename "$model")/${scene}_s$(printf %02d "$seed")_p$passes"
            "$bin/infer" --input "${prefix}_p$passes.exr" --model "$model" \
                --reference "$scenes/$scene/reference.exr" --output "$report.exr" \
                >/dev/null 2>&1
        done
    done
done
python3 - "$out/$(basename "$model")" <<'PY'
import json, pathlib, statistics, sys
rows = {}
for f in sorted(pathlib.Path(sys.argv[1]).glob("*_report.json")):
    scene, seed, passes = f.name[: -len("_report.json")].rsplit("_", 2)
    r = json.loads(f.read_text())
    rows.setdefault((scene, int(passes[1:])), []).append((seed, r["output"] / min(r["levels"])))
print("| scene | passes | seeds | max | median | seeds above 1.05 |")
print("|---|---|---|---|---|---|")
for (scene, passes), v in sorted(rows.items()):
    ratios = [x for _, x in v]
    above = ", ".join(f"{s[1:]} ({x:.2f})" for s, x in v if x > 1.05) or "none"
    print(f"| {scene} | {passes} | {len(v)} | {max(ratios):.3f} | {statistics.median(ratios):.3f} | {above} |")
PY
