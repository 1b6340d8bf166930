#!/usr/bin/env bash
# A dataset's training references rendered on a short-lived many-core node (docs/datagen.md,
# "References on another machine").
#
# A scene's reference is one long run that writes one small image: on `large`, more than half
# of a scene's render time for ≈ 0.3 MB, against ≈ 13 MB of input bundles. A node that is
# offline, bare, limited in time and hands back ≤ 8 files of ≤ 16 MiB can therefore render the
# references of many scenes (`datagen render --jobs references`) while the bundles are rendered
# where training reads them (`--jobs inputs`). Three steps:
#
#   scripts/device/references.sh pack [--target-dir DIR]          # here: stripped datagen
#   scripts/device/references.sh run  --config F [--budget S] [datagen selection …]   # there
#   scripts/device/references.sh unpack --out DATASET FILES…      # here: into the dataset
#
# `run` renders until its budget is spent (concurrent shards, each on a share of the cores),
# then archives the finished references with their records into $OUT (parts of ≤ 15 MiB);
# a reference cut by the budget is left out (its record is written after its image). `unpack`
# adds them to a dataset directory of the same config: `datagen render` then skips those jobs,
# and `datagen render --jobs inputs` (or a plain render) completes the scenes.
set -euo pipefail

die() { echo "references.sh: $*" >&2; exit 1; }
usage() { sed -n '2,19p' "$0" | sed 's/^# \{0,1\}//'; }

cd "$(dirname "$0")/../.."
PACK=.refs-node

pack() {
    local target="${CARGO_TARGET_DIR:-target}"
    while [ $# -gt 0 ]; do
        case "$1" in
            --target-dir) target="$2"; shift 2 ;;
            -h|--help) usage; exit 0 ;;
            *) die "pack: unknown option $1" ;;
        esac
    done
    [ -x "$target/release/datagen" ] ||
        die "pack: $target/release/datagen missing (cargo build --release --locked -p datagen)"
    rm -rf "$PACK"
    mkdir -p "$PACK"
    strip -o "$PACK/datagen" "$target/release/datagen"
    xz -T2 -9 "$PACK/datagen"
    echo "packed $PACK ($(du -sh "$PACK" | cut -f1)); on the node, carry $PACK:"
    echo "  bash scripts/device/references.sh run --config configs/datagen/large.toml --budget 420 --splits train --per-family 1-21"
}

run() {
    local config="" budget=420 out="${OUT:-out/references-node}" shards=0
    local args=()
    while [ $# -gt 0 ]; do
        case "$1" in
            --config) config="$2"; shift 2 ;;
            --budget) budget="$2"; shift 2 ;;
            --out) out="$2"; shift 2 ;;
            --shards) shards="$2"; shift 2 ;;
            -h|--help) usage; exit 0 ;;
            *) args+=("$1"); shift ;;
        esac
    done
    [ -f "$config" ] || die "run: --config $config: no such file"
    [ -f "$PACK/datagen.xz" ] || die "run: $PACK/datagen.xz missing: run \`$0 pack\` and carry $PACK"
    mkdir -p "$out"
    out=$(cd "$out" && pwd)
    local work bin data cores
    work=$(mktemp -d /tmp/references.XXXXXX)
    bin="$work/datagen"
    data="$work/data"
    xz -dc "$PACK/datagen.xz" >"$bin"
    chmod +x "$bin"
    cores=$(nproc)
    # A 128² reference pass does not keep 16 cores busy: four shards of four threads render
    # more scenes in the same time than one shard of sixteen.
    [ "$shards" -gt 0 ] || shards=$(( cores >= 8 ? cores / 4 : 1 ))
    local threads=$(( cores / shards ))
    echo "== references.sh run: $(date -u +%FT%TZ), $cores cores, $shards shards × $threads threads, budget $budget s" | tee "$out/log.txt"
    local pids=()
    for ((i = 0; i < shards; i++)); do
        timeout --signal=INT "$budget" "$bin" render --config "$config" --out "$data" \
            --jobs references --shard "$i/$shards" --threads "$threads" --quiet "${args[@]}" \
            >>"$out/log.txt" 2>&1 &
        pids+=($!)
    done
    for p in "${pids[@]}"; do wait "$p" || true; done
    # Finished references: a record and its image (the record is written last).
    local list="$work/finished.txt"
    (cd "$data" && for r in records/*/reference.json; do
        [ -f "$r" ] || continue
        local id
        id=$(basename "$(dirname "$r")")
        [ -f "references/$id.exr" ] && printf '%s\n%s\n' "$r" "references/$id.exr"
    done) >"$list"
    local n=$(( $(wc -l <"$list") / 2 ))
    echo "finished references: $n" | tee -a "$out/log.txt"
    [ "$n" -gt 0 ] || die "run: no reference finished within $budget s"
    tar cf - -C "$data" -T "$list" | split -b 15m -d - "$out/references.tar.part"
    ls -la "$out" | tee -a "$out/log.txt"
}

unpack() {
    local dataset=""
    local files=()
    while [ $# -gt 0 ]; do
        case "$1" in
            --out) dataset="$2"; shift 2 ;;
            -h|--help) usage; exit 0 ;;
            *) files+=("$1"); shift ;;
        esac
    done
    [ -n "$dataset" ] || die "unpack: --out DATASET missing"
    [ "${#files[@]}" -gt 0 ] || die "unpack: no references.tar.part* files given"
    mkdir -p "$dataset/records"
    # The parts in name order are one tar archive; existing files of the dataset are kept
    # (a reference rendered here already is the same job).
    local before after
    before=$(find "$dataset/records" -name reference.json | wc -l)
    cat "${files[@]}" | tar xf - -C "$dataset" --skip-old-files
    after=$(find "$dataset/records" -name reference.json | wc -l)
    echo "unpacked $((after - before)) references into $dataset ($after in all); \`datagen render --jobs inputs\` renders their bundles"
}

case "${1:-}" in
    pack) shift; pack "$@" ;;
    run) shift; run "$@" ;;
    unpack) shift; unpack "$@" ;;
    -h|--help|"") usage ;;
    *) die "unknown command $1 (pack, run or unpack)" ;;
esac
