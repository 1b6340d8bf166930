#!/usr/bin/env bash
# The GPU training job as one self-contained script (docs/training.md, "Training on a GPU node").
#
# A cluster GPU node here is offline, short-lived and bare: it gets the repository's working
# tree (≤ 64 MiB with what the job brings), runs ≤ 9 minutes, and hands back ≤ 8 files of
# ≤ 16 MiB. So the job is split in two:
#
#   scripts/device/train_gpu.sh pack [options]   # here, with a network: builds and packs .gpu/
#   scripts/device/train_gpu.sh run  [options]   # there, offline: times, trains, reports
#
# `pack` builds release binaries with the `wgpu` feature (stripped, one xz archive), downloads the
# Vulkan loader (Debian's libvulkan1; the node's NVIDIA driver brings the Vulkan driver itself),
# and copies a dataset's scenes and converged references without its input bundles: the node
# renders the inputs itself on its CPU cores (deterministic, so the same bundles as here) in
# about a minute, instead of carrying hundreds of MiB. `run` then, inside a wall-time budget:
#   1. checks the adapter (the log names it), 2. times a training step of the preset at the
#   paper's batch and at larger ones (`bench`), 3. times the reconstruction of a 1280×720
#   bundle (`bench_infer`, the preset and the shipped `small` preset), 4. renders the inputs
#   (`datagen render`), 5. trains for the time left (`train --time`, from `--init` weights if
#   packed), 6. scores the weights on the test split and reconstructs a rendered 1280×720 image
#   with them (`infer --backend wgpu`), 7. leaves ≤ 8 files in $OUT: log.txt, timings.json,
#   model.json, model.bpk, metrics.csv, curves.png, eval_test.json, infer.txt.
#
# Continue a run: copy the returned model.json + model.bpk into a folder and pack again with
# `--init FOLDER` (the next run starts from those weights with a fresh optimiser).
set -euo pipefail

usage() {
    sed -n '2,24p' "$0" | sed 's/^# \{0,1\}//'
    cat <<'EOF'

pack options:
  --seed-data DIR    dataset whose scenes + references are packed (default data/small, made by
                     `datagen render --config configs/datagen/small.toml --out data/small`);
                     `none`: pack nothing, the node renders the references too
  --init DIR         trained model folder (model.json + model.bpk) to continue from
  --target-dir DIR   cargo target folder of the wgpu build (default $GPU_TARGET_DIR or target-gpu;
                     not the usual one: the wgpu binaries would replace the CPU-only ones)
  --no-build         pack binaries already built in the target folder

run options (defaults: the paper preset on the `small` dataset):
  --budget S         wall-time budget of the whole run in seconds (default 500)
  --out DIR          result folder (default $OUT, else out/gpu-run)
  --preset P         network preset to time and train (default paper)
  --datagen-config F dataset config rendered on the node (default configs/datagen/small.toml)
  --datagen-args "…" more `datagen render` options, e.g. "--splits train --per-family 1-4": a
                     slice of `large` (all ten families) rendered on the node's CPU cores, its
                     references too (pack with --seed-data none; `--config-extra` a file with
                     `val_split = ""`, as a slice has no validation scenes)
  --patch N --stride N --batch N --lr X   training patches and Adam (default 64, 32, 16, 1e-4)
  --config-extra F   TOML lines appended to the training config the run writes (e.g.
                     `screen_levels` to match --init weights trained with them); a key the run
                     writes already (dataset, preset, patch, stride, batch, lr, epochs, seed,
                     output, init, backend, cache_images) is a TOML error
  --bench-batches "A B …"   batches timed (default "8 16 28"; "" times none: on an H200 the paper preset's
                     batches from 64 of 64² need a buffer above the device's limit; a failing
                     batch is left out)
  --bench-patch N    patch side of the timed steps (default 64, the paper's)
  --no-infer-bench   skip the 1280×720 reconstruction timings (step 3; a continued run)
  --bench-steps N    timed steps per batch (default 5)
  --infer-size WxH   bundle size of the inference timings (default 1280x720)
  --reserve S        seconds kept after training for scoring and inference (default 75)
EOF
}

die() { echo "train_gpu.sh: $*" >&2; exit 1; }

cd "$(dirname "$0")/../.."
PACK=.gpu
BINS="train bench infer bench_infer datagen"

pack() {
    local seed=data/small init="" target="${GPU_TARGET_DIR:-target-gpu}" build=1
    while [ $# -gt 0 ]; do
        case "$1" in
            --seed-data) seed="$2"; shift 2 ;;
            --init) init="$2"; shift 2 ;;
            --target-dir) target="$2"; shift 2 ;;
            --no-build) build=0; shift ;;
            -h|--help) usage; exit 0 ;;
            *) die "pack: unknown option $1 (see --help)" ;;
        esac
    done
    if [ "$seed" != none ] && [ ! -d "$seed/references" ]; then
        die "pack: $seed/references not found: render the dataset first (datagen render --config configs/datagen/small.toml --out $seed) or pass --seed-data none"
    fi
    if [ -n "$init" ] && { [ ! -f "$init/model.json" ] || [ ! -f "$init/model.bpk" ]; }; then
        die "pack: --init $init: needs model.json and model.bpk"
    fi
    if [ "$build" = 1 ]; then
        CARGO_TARGET_DIR="$target" cargo build --release --locked -p train -p infer \
            --features train/wgpu,infer/wgpu
        CARGO_TARGET_DIR="$target" cargo build --release --locked -p datagen
    fi
    rm -rf "$PACK"
    mkdir -p "$PACK/bin" "$PACK/debs"
    for b in $BINS; do
        [ -x "$target/release/$b" ] || die "pack: $target/release/$b missing (build without --no-build)"
        strip -o "$PACK/bin/$b" "$target/release/$b"
    done
    # One archive with a dictionary larger than any binary: the four wgpu binaries share most of
    # their code, so xz stores it about once (≈ 20 MiB for 220 MiB; a few minutes here).
    echo "compressing the binaries (xz -9e, a few minutes) ..."
    tar cf - -C "$PACK/bin" $BINS | xz -T2 -9e --lzma2=preset=9e,dict=256MiB >"$PACK/bin.tar.xz"
    rm -rf "$PACK/bin"
    # The Vulkan loader for an amd64 node, whatever this machine's architecture.
    local lists
    lists=$(mktemp -d)
    mkdir -p "$lists/partial"
    local o=(-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 "-oDir::State::Lists=$lists")
    apt-get "${o[@]}" update >/dev/null
    # GLVND + EGL too: headless, the NVIDIA Vulkan driver is reached through libEGL_nvidia.
    (cd "$PACK/debs" && apt-get "${o[@]}" download libvulkan1 libglvnd0 libegl1 >/dev/null)
    rm -rf "$lists"
    if [ "$seed" != none ]; then
        # Scenes, references and their records: `datagen render` skips those jobs (their
        # records and files are intact) and renders only the input bundles.
        mkdir -p "$PACK/data"
        cp -r "$seed/scenes" "$seed/references" "$PACK/data/"
        for r in "$seed"/records/*/reference.json; do
            local scene
            scene=$(basename "$(dirname "$r")")
            mkdir -p "$PACK/data/records/$scene"
            cp "$r" "$PACK/data/records/$scene/"
        done
    fi
    if [ -n "$init" ]; then
        if git ls-files --error-unmatch "$init/model.bpk" >/dev/null 2>&1 &&
            git diff --quiet -- "$init/model.bpk" "$init/model.json"; then
            # Committed weights (models/default, models/paper) travel with the working tree:
            # name them instead of packing a second copy into the 64 MiB.
            git ls-files --full-name "$init/model.bpk" | sed 's#/model.bpk$##' >"$PACK/init-path"
        else
            mkdir -p "$PACK/init"
            cp "$init/model.json" "$init/model.bpk" "$PACK/init/"
        fi
    fi
    local tree packed
    tree=$(git ls-files -z --cached --others --exclude-standard | du -cb --files0-from=- 2>/dev/null | tail -1 | cut -f1)
    packed=$(du -sb "$PACK" | cut -f1)
    echo "packed $PACK: $((packed / 1024 / 1024)) MiB; working tree $((tree / 1024 / 1024)) MiB; together $(((tree + packed) / 1024 / 1024)) MiB of the node's 64"
    # The node takes the working tree as it is on disk: tracked files the run does not read
    # (other models' weights, contact sheets) can be moved aside for the call and restored with
    # `git checkout -- PATHS` (docs/training.md).
    [ $((tree + packed)) -le $((62 * 1024 * 1024)) ] ||
        die "pack: over the 64 MiB a node takes; $PACK is complete: move tracked files the node does not need out of the working tree for the call (e.g. models/paper/model.bpk, *.safetensors, docs/images/*contact-sheet*.png), then git checkout them back"
    echo "on the node (repository root, carry $PACK): bash scripts/device/train_gpu.sh run --budget 500"
}

# Seconds since the run started.
elapsed() { echo $(( $(date +%s) - START )); }

run() {
    local budget=500 out="${OUT:-out/gpu-run}" preset=paper dgconfig=configs/datagen/small.toml
    local patch=64 stride=32 batch=16 lr=1e-4 bench_batches="8 16 28" bench_steps=5
    local bench_patch=64 infer_size=1280x720 reserve=75 extra="" infer_bench=1 dgargs=""
    while [ $# -gt 0 ]; do
        case "$1" in
            --budget) budget="$2"; shift 2 ;;
            --out) out="$2"; shift 2 ;;
            --preset) preset="$2"; shift 2 ;;
            --datagen-config) dgconfig="$2"; shift 2 ;;
            --datagen-args) dgargs="$2"; shift 2 ;;
            --patch) patch="$2"; shift 2 ;;
            --stride) stride="$2"; shift 2 ;;
            --batch) batch="$2"; shift 2 ;;
            --lr) lr="$2"; shift 2 ;;
            --bench-batches) bench_batches="$2"; shift 2 ;;
            --bench-steps) bench_steps="$2"; shift 2 ;;
            --bench-patch) bench_patch="$2"; shift 2 ;;
            --config-extra) extra="$2"; shift 2 ;;
            --no-infer-bench) infer_bench=0; shift ;;
            --infer-size) infer_size="$2"; shift 2 ;;
            --reserve) reserve="$2"; shift 2 ;;
            -h|--help) usage; exit 0 ;;
            *) die "run: unknown option $1 (see --help)" ;;
        esac
    done
    [ -z "$extra" ] || [ -f "$extra" ] || die "run: --config-extra $extra: no such file"
    [ -f "$PACK/bin.tar.xz" ] || die "run: $PACK/bin.tar.xz missing: run \`$0 pack\` first and carry $PACK"
    local iw=${infer_size%x*} ih=${infer_size#*x}
    START=$(date +%s)
    mkdir -p "$out"
    out=$(cd "$out" && pwd)
    local work
    work=$(mktemp -d /tmp/train-gpu.XXXXXX)
    exec > >(tee "$out/log.txt") 2>&1
    echo "== train_gpu.sh run: budget ${budget} s, preset $preset, $(date -u +%FT%TZ), $(nproc) CPU cores"

    # 1. Binaries, Vulkan loader, driver manifest, adapter.
    mkdir -p "$work/bin"
    xz -dc "$PACK/bin.tar.xz" | tar xf - -C "$work/bin"
    local bin="$work/bin"
    if ! ldconfig -p | grep -q 'libvulkan\.so\.1' || ! ldconfig -p | grep -q 'libGLdispatch\.so\.0'; then
        echo "Vulkan loader or GLVND missing: unpacking $(ls "$PACK"/debs | tr '\n' ' ')"
        for f in "$PACK"/debs/*.deb; do dpkg -x "$f" /; done
        ldconfig
    fi
    # The driver's own manifest names its GLX library, whose vk_icdGetInstanceProcAddr returns
    # no vkCreateInstance without an X display (seen on an H200 node, driver 580.159.04: "Found
    # no drivers"); the same Vulkan driver is reachable headless through its EGL library.
    if ldconfig -p | grep -q 'libEGL_nvidia\.so\.0'; then
        local icd="$work/nvidia_egl_icd.json"
        printf '{"file_format_version": "1.0.1", "ICD": {"library_path": "libEGL_nvidia.so.0", "api_version": "1.3.0"}}\n' >"$icd"
        export VK_DRIVER_FILES="$icd" VK_ICD_FILENAMES="$icd"
        echo "Vulkan driver manifest: $icd (libEGL_nvidia.so.0, headless)"
    elif ! grep -qs nvidia /usr/share/vulkan/icd.d/*.json /etc/vulkan/icd.d/*.json; then
        # Containers may mount the NVIDIA driver without registering its Vulkan manifest.
        for icd in /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json /usr/share/vulkan/icd.d/nvidia_icd.json; do
            if [ -f "$icd" ]; then
                export VK_DRIVER_FILES="$icd" VK_ICD_FILENAMES="$icd"
                echo "Vulkan driver manifest: $icd"
                break
            fi
        done
    fi
    command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader || true

    # 2. Training-step timings (random weights and patches; the first step is a warm-up).
    local timings="$work/timings"
    mkdir -p "$timings"
    for b in $bench_batches; do
        echo "== bench: $preset preset, training step at batch $b of ${bench_patch}², forward at 256² ($(elapsed) s)"
        "$bin/bench" --backend wgpu --preset "$preset" --batch "$b" --patch "$bench_patch" \
            --infer-size 256 --steps "$bench_steps" --peer none --output "$timings/step_b$b.json" ||
            echo "bench at batch $b failed (out of memory?): left out"
    done

    # 3. Reconstruction timings at the inference size: the preset and the shipped weights'.
    local ship_preset
    ship_preset=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["preset"])' models/default/model.json)
    [ "$infer_bench" = 1 ] || ship_preset=""
    for p in ${ship_preset:+"$preset" "$ship_preset"}; do
        for tile in 0 512; do
            echo "== bench_infer: $p preset, ${iw}x${ih}, tile $tile ($(elapsed) s)"
            "$bin/bench_infer" --backend wgpu --engine burn --preset "$p" --size "$iw" \
                --height "$ih" --tile "$tile" --repeats 3 --peer none \
                --output "$timings/infer_${p}_tile$tile.json" ||
                echo "bench_infer $p tile $tile failed: left out"
        done
    done

    # 4. The training inputs, rendered on the node's cores (references come packed).
    local data="$work/data" datagen_s
    mkdir -p "$data"
    [ -d "$PACK/data" ] && cp -r "$PACK/data/." "$data/"
    echo "== datagen render --config $dgconfig $dgargs ($(elapsed) s)"
    local t0
    t0=$(date +%s)
    # shellcheck disable=SC2086 # $dgargs is a list of options
    "$bin/datagen" render --config "$dgconfig" --out "$data" --quiet $dgargs
    if [ -n "$dgargs" ]; then
        # A slice of a dataset ends without a manifest (the rest is not rendered): list the
        # scenes it rendered.
        "$bin/datagen" manifest --config "$dgconfig" --out "$data" --partial
    fi
    datagen_s=$(( $(date +%s) - t0 ))
    echo "datagen: ${datagen_s} s"

    # 5. Train for the time left.
    local run_dir="$work/run" init_line="" train_s
    if [ -f "$PACK/init/model.bpk" ]; then
        init_line="init = \"$(cd "$PACK/init" && pwd)\""
    elif [ -f "$PACK/init-path" ]; then
        local init_dir
        init_dir=$(cat "$PACK/init-path")
        [ -f "$init_dir/model.bpk" ] || die "run: the packed --init $init_dir is not in this working tree"
        init_line="init = \"$(cd "$init_dir" && pwd)\""
    fi
    cat >"$work/train.toml" <<EOF
# written by scripts/device/train_gpu.sh run
backend = "wgpu"
dataset = "$data"
preset = "$preset"
patch = $patch
stride = $stride
batch = $batch
epochs = 1000
lr = $lr
seed = 1
cache_images = 512
output = "$run_dir"
$init_line
EOF
    if [ -n "$extra" ]; then
        echo "# from --config-extra $extra" >>"$work/train.toml"
        cat "$extra" >>"$work/train.toml"
    fi
    echo "== training config:"; grep -v '^#' "$work/train.toml"
    train_s=$(( budget - $(elapsed) - reserve ))
    [ "$train_s" -ge 10 ] || train_s=10
    echo "== train: $train_s s ($(elapsed) s)"
    t0=$(date +%s)
    "$bin/train" --config "$work/train.toml" --time "$train_s" 2>&1 | tr '\r' '\n' | grep -v '^\s*$' | grep -v 'patches, ' || true
    train_s=$(( $(date +%s) - t0 ))
    [ -f "$run_dir/model.bpk" ] || die "training wrote no weights (see the log)"

    # 6. Score the weights, then reconstruct a rendered image of the inference size with them
    #    and with the shipped weights.
    echo "== train --evaluate test ($(elapsed) s)"
    "$bin/train" --config "$work/train.toml" --evaluate test || echo "evaluation failed"
    echo "== infer at ${iw}x${ih} ($(elapsed) s)"
    sed -e "s/name=\"res\" value=\"[0-9]*\"/name=\"res\" value=\"$iw\"/" \
        -e "s/<integer name=\"height\" value=\"\$res\"\/>/<integer name=\"height\" value=\"$ih\"\/>/" \
        scenes/default/scene.xml >"scenes/default/.gpu-${iw}x${ih}.xml"
    {
        "$bin/infer" --scene "scenes/default/.gpu-${iw}x${ih}.xml" --passes 4 --photons 400000 \
            --backend wgpu --output "$work/infer/shipped.exr" 2>&1 | tr '\r' '\n' | grep -E 'adapter|rendered|reconstructed' || true
        "$bin/infer" --input "$work/infer/shipped_bundle.exr" --model "$run_dir" --backend wgpu \
            --output "$work/infer/trained.exr" 2>&1 | tr '\r' '\n' | grep -E 'adapter|reconstructed' || true
    } | tee "$out/infer.txt"
    rm -f "scenes/default/.gpu-${iw}x${ih}.xml"

    # 7. What comes back.
    cp "$run_dir/model.json" "$run_dir/model.bpk" "$run_dir/metrics.csv" "$out/"
    cp "$run_dir/curves.png" "$out/" 2>/dev/null || true
    cp "$run_dir/eval_test.json" "$out/" 2>/dev/null || true
    python3 - "$timings" "$out/timings.json" "$datagen_s" "$train_s" "$(elapsed)" "$preset" "$batch" <<'EOF'
import glob, json, os, sys
src, dst, datagen_s, train_s, total_s, preset, batch = sys.argv[1:]
result = {"preset": preset, "train_batch": int(batch), "datagen_s": int(datagen_s),
          "train_s": int(train_s), "total_s": int(total_s), "step": {}, "infer": {}}
for f in sorted(glob.glob(os.path.join(src, "*.json"))):
    name = os.path.basename(f)[:-5]
    data = json.load(open(f))
    if name.startswith("step_"):
        step = data["burn"]["train_step_s"]
        data["patches_per_s"] = data["batch"] / step if step else None
        result["step"][name] = data
    else:
        result["infer"][name] = data
json.dump(result, open(dst, "w"), indent=1)
EOF
    echo "== done in $(elapsed) s; results in $out: $(ls "$out" | tr '\n' ' ')"
}

case "${1:-}" in
    pack) shift; pack "$@" ;;
    run) shift; run "$@" ;;
    -h|--help|"") usage ;;
    *) die "unknown command $1 (pack or run; see --help)" ;;
esac
