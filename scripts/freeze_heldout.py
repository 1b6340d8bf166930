#!/usr/bin/env python3
"""Freeze a dataset's evaluation scenes into a committed held-out set.

Copies, for every scene of the given splits that has a converged evaluation reference
(`datagen evaluation-references`), its generated scene folder (XML, PLY meshes, textures) and
that reference into OUT/<scene id>/ (scene.xml, reference.exr), and writes OUT/scenes.json
(provenance per scene) and the `[[scenes]]` tables of the evaluate configs named by --config.

Why: the machines this project renders on are wiped between sessions, and converging these
references takes hours; a frozen copy lets any checkout run the equal-time study on scenes no
network was trained on in minutes. The copy is frozen on purpose: the XML beside each reference
is the one it was rendered from, whatever later changes to the scene generators do.

    python3 scripts/freeze_heldout.py data/large scenes/heldout --splits test \
        --config configs/eval/heldout-families.toml=lamp,tabletop,exterior,material,textured \
        --config configs/eval/paper-heldout-families.toml=lamp,tabletop,exterior,material,textured

A config is rewritten from the line `# --- scenes (scripts/freeze_heldout.py) ---` on; the lines
above it (model, passes, peers, ...) are kept, so it must exist and hold that line.
"""

import argparse
import hashlib
import json
import shutil
import sys
from pathlib import Path

MARKER = "# --- scenes (scripts/freeze_heldout.py) ---"


def sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def fail(message: str) -> None:
    print(f"freeze_heldout: error: {message}", file=sys.stderr)
    sys.exit(2)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset", type=Path, help="dataset directory (with manifest.json)")
    ap.add_argument("out", type=Path, help="folder of the frozen set, e.g. scenes/heldout")
    ap.add_argument("--splits", default="test", help="comma-separated splits (default: test)")
    ap.add_argument(
        "--max-noise",
        type=float,
        default=0.25,
        help="freeze only references whose noise is at most this fraction of the input error "
        "they were converged against (default 0.25; their target is 0.1, flagged ones may be "
        "far above it and would measure their own noise)",
    )
    ap.add_argument(
        "--config",
        action="append",
        default=[],
        help="evaluate config to write the scenes into: PATH or PATH=family,family",
    )
    args = ap.parse_args()

    manifest_path = args.dataset / "manifest.json"
    try:
        manifest = json.loads(manifest_path.read_text())
    except (OSError, json.JSONDecodeError) as e:
        fail(f"{manifest_path}: {e}")
    # Every config is checked before anything is copied: a bad one leaves the set as it was.
    for spec in args.config:
        path = Path(spec.partition("=")[0])
        try:
            if MARKER not in path.read_text():
                fail(f"{path}: no line `{MARKER}` to write the scenes after")
        except OSError as e:
            fail(f"{path}: {e}")
    splits = set(args.splits.split(","))
    config_name = manifest.get("config_name", manifest.get("name", "?"))
    frozen = []
    for scene in manifest["scenes"]:
        if scene["split"] not in splits:
            continue
        ev = scene.get("evaluation_reference")
        if ev is None:
            print(f"skipped {scene['id']}: no evaluation reference", file=sys.stderr)
            continue
        fraction = ev["noise"] / ev["input_relmse"]
        if not fraction <= args.max_noise:
            print(
                f"skipped {scene['id']}: reference noise {fraction:.2f} x its input error "
                f"(above --max-noise {args.max_noise})",
                file=sys.stderr,
            )
            continue
        src_ref = args.dataset / ev["path"]
        if sha256(src_ref) != ev["sha256"]:
            fail(f"{src_ref}: checksum differs from the manifest's")
        src_dir = (args.dataset / scene["xml"]).parent
        dst = args.out / scene["id"]
        if dst.exists():
            shutil.rmtree(dst)
        args.out.mkdir(parents=True, exist_ok=True)
        shutil.copytree(src_dir, dst)
        shutil.copyfile(src_ref, dst / "reference.exr")
        size = scene.get("size") or [manifest["width"], manifest["height"]]
        frozen.append(
            {
                "id": scene["id"],
                "family": scene["family"],
                "split": scene["split"],
                "regime": scene.get("regime"),
                "size": size,
                "reference_sha256": ev["sha256"],
                "reference_passes": ev["passes"],
                "reference_photons_per_pass": ev["photons"],
                "reference_runs": len(ev["seeds"]),
                "reference_noise": ev["noise"],
                "input_relmse": ev["input_relmse"],
                "converged": ev["converged"],
                "seconds": ev["seconds"],
            }
        )
    if not frozen:
        fail(f"{manifest_path}: no scene of the splits {sorted(splits)} has a usable evaluation reference")
    source = {"config": config_name, "config_sha256": manifest.get("config_sha256")}
    # Scenes frozen by earlier calls stay (a later session converges more of them), but only
    # from the same dataset config: one set, one source.
    record_path = args.out / "scenes.json"
    if record_path.exists():
        earlier = json.loads(record_path.read_text())
        if earlier["source"] != source:
            fail(f"{record_path}: frozen from {earlier['source']}, not {source}")
        now = {s["id"] for s in frozen}
        frozen += [s for s in earlier["scenes"] if s["id"] not in now]
    frozen.sort(key=lambda s: s["id"])
    record = {"source": source, "scenes": frozen}
    record_path.write_text(json.dumps(record, indent=1) + "\n")

    for spec in args.config:
        path, _, fams = spec.partition("=")
        families = set(fams.split(",")) if fams else None
        path = Path(path)
        try:
            text = path.read_text()
        except OSError as e:
            fail(f"{path}: {e}")
        if MARKER not in text:
            fail(f"{path}: no line `{MARKER}` to write the scenes after")
        head = text[: text.index(MARKER)] + MARKER + "\n"
        chosen = [s for s in frozen if families is None or s["family"] in families]
        if not chosen:
            fail(f"{path}: no frozen scene of the families {sorted(families)}")
        if families is not None:
            missing = families - {s["family"] for s in chosen}
            if missing:
                print(f"{path}: no frozen scene of the families {sorted(missing)}", file=sys.stderr)
        body = []
        for s in chosen:
            d = args.out / s["id"]
            body.append(
                "\n[[scenes]]\n"
                f'name = "{s["id"]}"\n'
                f'xml = "{d / "scene.xml"}"\n'
                f'reference = "{d / "reference.exr"}"\n'
                f'reference_noise = {s["reference_noise"]:.6e}\n'
            )
        path.write_text(head + "".join(body))
        print(f"{path}: {len(chosen)} scenes")
    flagged = [s["id"] for s in frozen if not s["converged"]]
    print(
        f"{args.out}: {len(frozen)} scenes in the set"
        + (f"; flagged (noise above its target): {', '.join(flagged)}" if flagged else "")
    )


if __name__ == "__main__":
    main()
