#!/usr/bin/env bash
# The guard's tuning grid (docs/results.md, "Never worse than its inputs"): every validation
# bundle reconstructed with the shipped weights at each (κ, λ) of the grid; per pair, the
# bundles above 1.05× the best input level, the worst and the median ratio.
#
#   scripts/guard_grid.sh BIN_DIR MODEL_DIR OUT_DIR [KAPPAS] [LAMBDAS]
#
# BIN_DIR holds release binaries (`render`, `bundle_info`, `infer`). The validation bundles:
# data/small's `val` split (the bundles `datagen render --config configs/datagen/small.toml`
# writes; 6 scenes x 3 seeds x 8/16/32 passes) and six renderer validation scenes at 64x64,
# rendered here into OUT_DIR (32 and 256 passes at 2 000 and 20 000 photons per pass, seed 1;
# references: standard SPPM, 2048 passes x 100 000 photons, seed 11; about 25 min on 2 cores,
# skipped when present). None of them is a stress, external or test scene.
set -euo pipefail
bin="$1"; model="$2"; out="$3"
kappas="${4:-12 16 24 32 48}"; lambdas="${5:-4 8 16 32 64}"
root="$(cd "$(dirname "$0")/.." && pwd)"
mkdir -p "$out/tune" "$out/reports"
cases="$out/cases.tsv"; : > "$cases"
for scene in cornell-diffuse glass-mirror-spheres rough-materials many-lights spot-point-thinlens mixed-features; do
    xml="$root/scenes/validation/$scene/scene.xml"
    depth=$(grep -o 'name="max_depth" value="[0-9]*"' "$xml" | grep -o '[0-9]\+')
    if [ ! -f "$out/tune/${scene}_ref.exr" ]; then
        "$bin/render" "$xml" -D res=64 --integrator sppm --photons 100000 --passes 2048 --seed 11 \
            --max-depth "$depth" --out "$out/tune/${scene}_ref" >/dev/null 2>&1
        "$bin/bundle_info" "$out/tune/${scene}_ref_p2048.exr" --exr y "$out/tune/${scene}_ref.exr" >/dev/null
    fi
    for photons in 20000 2000; do
        prefix="$out/tune/${scene}_$photons"
        [ -f "${prefix}_p0256.exr" ] || "$bin/render" "$xml" -D res=64 --integrator sppm-ml \
            --photons "$photons" --passes 32,256 --seed 1 --max-depth "$depth" --out "$prefix" >/dev/null 2>&1
        for p in 0032 0256; do
            printf '%s\t%s\t%s\n' "${scene}_${photons}_p$p" "${prefix}_p$p.exr" "$out/tune/${scene}_ref.exr" >> "$cases"
        done
    done
done
python3 - "$root/data/small" >> "$cases" <<'PY'
import json, pathlib, sys
root = pathlib.Path(sys.argv[1])
manifest = json.loads((root / "manifest.json").read_text())
for s in manifest["scenes"]:
    if s["split"] == "val":
        for b in sorted((root / "bundles" / s["id"]).glob("*.exr")):
            print(f"{s['id']}_{b.stem}\t{b}\t{root / s['reference']}")
PY
for kappa in $kappas; do
    for lambda in $lambdas; do
        while IFS=$'\t' read -r name bundle reference; do
            "$bin/infer" --input "$bundle" --model "$model" --reference "$reference" --guard "$kappa" \
                --guard-target-noise "$lambda" --output "$out/reports/k${kappa}_l${lambda}_$name.exr" \
                >/dev/null 2>&1
        done < "$cases"
    done
done
python3 - "$out/reports" <<'PY'
import json, pathlib, statistics, sys
rows = {}
for f in pathlib.Path(sys.argv[1]).glob("*_report.json"):
    kappa, lam, _ = f.name.split("_", 2)
    r = json.loads(f.read_text())
    rows.setdefault((float(kappa[1:]), float(lam[1:])), []).append(r["output"] / min(r["levels"]))
print("| κ | λ | bundles | above 1.05 | max | median |")
print("|---|---|---|---|---|---|")
for (kappa, lam), v in sorted(rows.items()):
    print(f"| {kappa:g} | {lam:g} | {len(v)} | {sum(x > 1.05 for x in v)} | {max(v):.3f} | {statistics.median(v):.3f} |")
PY
