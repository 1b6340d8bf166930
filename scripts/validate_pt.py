#!/usr/bin/env python3
"""Validate the path tracer against Mitsuba 3 on the same XML (issue 2, "Must show 1").

For every validation scene (scenes/validation/*/scene.xml) and every external scene
(../shared/scenes/external/*/scene.xml) this script

1. renders a Mitsuba 3 reference with its `path` integrator (`volpath` for scenes whose file
   names it: participating media; llvm_ad_rgb, box filter, 128x128,
   the scene's max_depth; default 4096 spp in chunks of 512 with distinct seeds) and caches it
   under out/validation/<scene>/ (keyed by a hash of the scene files and the settings);
2. renders the same XML with our `render --integrator path` at the same spp and resolution;
3. compares them after 4x4 box downsampling:
       relMSE = mean((ours - mitsuba)^2 / (mitsuba^2 + 1e-2))      must be <= 1e-3
       |mean(ours) - mean(mitsuba)| / mean(mitsuba), per channel   must be <= 1 %
   and estimates the part of relMSE that noise alone explains ("noise floor"), from the spread
   of Mitsuba's chunks (our image is assumed to have the same per-sample variance);
4. prints a markdown table, writes side-by-side PNGs (Mitsuba | ours | 4x4-downsampled
   relative difference, red = ours brighter, blue = ours darker, full scale +-20 %) and, with
   --doc, puts the table into docs/validation.md between the validate_pt markers.

Mitsuba is a development tool only (`pip install mitsuba`); nothing in the project needs it at
run time. External scenes whose meta.json says they are not path-traceable (water-caustic:
SPPM only, see its README) are listed but not compared.

    python3 scripts/validate_pt.py                       # everything, 4096 spp
    python3 scripts/validate_pt.py --scenes cbox,textured-diffuse --spp 1024
    python3 scripts/validate_pt.py --refs-only           # only build the Mitsuba cache
    python3 scripts/validate_pt.py --doc docs/validation.md
    python3 scripts/validate_pt.py --scene-root /tmp/fam   # generated scenes: datagen scenes --out /tmp/fam

With --scene-root DIR the scenes are DIR/*/scene.xml instead (group "generated": datagen's
scenes, whose film has its dataset's size, so only the 4x4 divisibility is checked).
"""

import argparse
import hashlib
import json
import os
import re
import shlex
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
EXTERNAL = (ROOT / ".." / "shared" / "scenes" / "external").resolve()
VALIDATION = ROOT / "scenes" / "validation"
RES = 128
DOWN = 4
REL_MSE_MAX = 1e-3
MEAN_TOL = 0.01
CHUNK_SPP = 512
DOC_BEGIN = "<!-- validate_pt:begin -->"
DOC_END = "<!-- validate_pt:end -->"


def mitsuba():
    """Import Mitsuba lazily (only needed when a reference has to be rendered or an EXR read)."""
    import mitsuba as mi

    if mi.variant() is None:
        mi.set_variant("llvm_ad_rgb", "scalar_rgb")
    return mi


class Scene:
    """One scene to validate: where it is and the path-tracing settings both renderers use."""

    def __init__(self, name, xml, group):
        self.name = name
        self.xml = xml
        self.group = group
        text = xml.read_text()
        self.defaults = {e.get("name"): e.get("value") for e in ET.fromstring(text).iter("default")}
        meta_path = xml.parent / "meta.json"
        self.meta = json.loads(meta_path.read_text()) if meta_path.exists() else {}
        if "max_depth" in self.defaults:
            self.max_depth = int(self.defaults["max_depth"])
        else:
            m = re.search(r'name="max_depth"\s+value="(-?\d+)"', text)
            self.max_depth = int(m.group(1)) if m else int(self.meta.get("max_depth", -1))
        m = re.search(r'name="rr_depth"\s+value="(\d+)"', text)
        self.rr_depth = int(m.group(1)) if m else int(self.meta.get("rr_depth", 5))
        m = re.search(r'name="hide_emitters"\s+value="(true|false)"', text)
        self.hide_emitters = bool(m) and m.group(1) == "true"
        self.has_integrator = "<integrator" in text
        # `direct` scenes are compared with Mitsuba's `direct` at the file's sample counts.
        integ = ET.fromstring(text).find("integrator")
        self.integrator = integ.get("type") if integ is not None else "path"
        counts = {e.get("name"): int(e.get("value")) for e in (integ if integ is not None else [])
                  if e.tag == "integer" and e.get("name", "").endswith("_samples")}
        shading = counts.get("shading_samples", 1)
        self.emitter_samples = counts.get("emitter_samples", shading)
        self.bsdf_samples = counts.get("bsdf_samples", shading)
        # The table's max_depth column: `direct` has none, it shows its sample counts instead.
        self.depth_label = (f"direct ({self.emitter_samples} emitter, {self.bsdf_samples} BSDF)"
                            if self.integrator == "direct" else str(self.max_depth))
        # Externals: the shared reference was made with `path` unless meta.json says otherwise.
        self.path_traceable = self.meta.get("integrator", "path") == "path"

    def files_hash(self, extra):
        """Hash of the XML, every file next to it (meshes, textures) and the settings."""
        h = hashlib.sha256(json.dumps(extra, sort_keys=True).encode())
        for p in sorted(self.xml.parent.rglob("*")):
            if p.is_file() and p.suffix.lower() in (".xml", ".obj", ".ply", ".serialized", ".png", ".exr", ".jpg",
                                                        ".jpeg", ".hdr", ".tga", ".bmp"):
                if p.name.startswith("reference"):
                    continue
                h.update(str(p.relative_to(self.xml.parent)).encode())
                h.update(p.read_bytes())
        return h.hexdigest()[:16]

    def load_params(self, spp):
        """Parameters for `mi.load_file`: only those the file declares with <default>."""
        params = {"res": RES, "spp": spp, "max_depth": self.max_depth}
        return {k: v for k, v in params.items() if k in self.defaults}


def discover(selected, root=None):
    """All validation and external scenes (or every DIR/*/scene.xml of `root`), optionally
    filtered by name."""
    scenes = []
    groups = (("generated", root),) if root else (("validation", VALIDATION), ("external", EXTERNAL))
    for group, base in groups:
        for xml in sorted(base.glob("*/scene.xml")):
            scenes.append(Scene(xml.parent.name, xml, group))
    if selected:
        names = set(selected.split(","))
        unknown = names - {s.name for s in scenes}
        if unknown:
            sys.exit(f"unknown scene(s): {', '.join(sorted(unknown))}")
        scenes = [s for s in scenes if s.name in names]
    return scenes


def downsample(img, f=DOWN):
    """Box-downsample an (H, W, C) image by f in both axes."""
    h, w, c = img.shape
    return img[: h - h % f, : w - w % f].reshape(h // f, f, w // f, f, c).mean(axis=(1, 3))


def read_exr(path):
    """Read an RGB EXR as float64 (H, W, 3)."""
    mi = mitsuba()
    return np.array(mi.Bitmap(str(path)), dtype=np.float64)[..., :3]


def write_exr(path, img):
    mi = mitsuba()
    tmp = path.with_suffix(".tmp.exr")
    mi.Bitmap(img.astype(np.float32)).write(str(tmp))
    os.replace(tmp, path)


def mitsuba_reference(scene, spp, out_dir, force):
    """Render (or load from the cache) the Mitsuba reference; returns (image, chunk_down, info).

    chunk_down: the 4x4-downsampled image of every chunk, for the noise estimate."""
    settings = {
        "spp": spp,
        "chunk_spp": CHUNK_SPP,
        "res": RES,
        "max_depth": scene.max_depth,
        "rr_depth": scene.rr_depth,
        "integrator": "path",
    }
    if scene.hide_emitters:  # only then: the cache keys of the other scenes stay as they were
        settings["hide_emitters"] = True
    if scene.integrator == "direct":
        settings.update(integrator="direct", emitter_samples=scene.emitter_samples,
                        bsdf_samples=scene.bsdf_samples)
    if scene.integrator == "volpath":
        settings["integrator"] = "volpath"
    key = scene.files_hash(settings)
    exr, npy, info_path = out_dir / "mitsuba.exr", out_dir / "mitsuba_chunks.npy", out_dir / "mitsuba.json"
    if not force and info_path.exists() and exr.exists() and npy.exists():
        info = json.loads(info_path.read_text())
        if info.get("key") == key:
            return read_exr(exr), np.load(npy), info
    mi = mitsuba()
    mi.set_variant("llvm_ad_rgb")
    chunks = max(1, spp // CHUNK_SPP)
    chunk_spp = spp // chunks
    sc = mi.load_file(str(scene.xml), **scene.load_params(chunk_spp))
    if scene.integrator == "direct":
        integrator = mi.load_dict({"type": "direct", "emitter_samples": scene.emitter_samples,
                                   "bsdf_samples": scene.bsdf_samples, "hide_emitters": scene.hide_emitters})
    else:
        kind = "volpath" if scene.integrator == "volpath" else "path"
        integrator = mi.load_dict({"type": kind, "max_depth": scene.max_depth, "rr_depth": scene.rr_depth,
                                   "hide_emitters": scene.hide_emitters})
    t0 = time.time()
    acc, downs = None, []
    for k in range(chunks):
        img = np.array(mi.render(sc, integrator=integrator, spp=chunk_spp, seed=9000 + k), dtype=np.float64)[..., :3]
        # The film is $res wide; its height is the scene's (square unless the scene says so).
        # A film with a crop window renders the window, whose sides must still divide by DOWN.
        cropped = "crop_width" in scene.xml.read_text() or "crop_height" in scene.xml.read_text()
        sized = "res" in scene.defaults  # generated scenes have their dataset's fixed film
        if (sized and img.shape[1] != RES and not cropped) or img.shape[0] % DOWN or img.shape[1] % DOWN:
            sys.exit(f"{scene.name}: Mitsuba rendered {img.shape[1]}x{img.shape[0]}, expected "
                     f"width {RES} (or a crop window) and sides divisible by {DOWN} (no $res default?)")
        acc = img if acc is None else acc + img
        downs.append(downsample(img))
        print(f"  mitsuba {scene.name}: chunk {k + 1}/{chunks}", file=sys.stderr, flush=True)
    seconds = time.time() - t0
    img = acc / chunks
    out_dir.mkdir(parents=True, exist_ok=True)
    write_exr(exr, img)
    np.save(npy, np.stack(downs).astype(np.float32))
    info = dict(settings, key=key, seconds=round(seconds, 1), variant="llvm_ad_rgb",
                mitsuba=mi.__version__, chunks=chunks, seeds=[9000, 9000 + chunks - 1],
                mean_rgb=[float(x) for x in img.mean(axis=(0, 1))])
    info_path.write_text(json.dumps(info, indent=2) + "\n")
    return img, np.stack(downs), info


def render_help(binary):
    return subprocess.run([str(binary), "--help"], capture_output=True, text=True).stdout


def ours_command(scene, binary, help_text, spp, seed, out_exr, out_png, threads):
    """The `render` command line for one scene (path tracer, 128x128, the scene's max_depth;
    `direct` scenes with the direct integrator at the file's sample counts, `volpath` scenes
    (participating media) with the volumetric path tracer)."""
    integrator = scene.integrator if scene.integrator in ("direct", "volpath") else "path"
    cmd = [str(binary), str(scene.xml), "--integrator", integrator, "--spp", str(spp), "--seed", str(seed),
           "--out", str(out_exr), "--png", str(out_png)]
    if threads:
        cmd += ["--threads", str(threads)]
    if integrator == "direct":
        if "res" in scene.defaults:
            cmd += ["-D", f"res={RES}"]
        if "spp" in scene.defaults:
            cmd += ["-D", f"spp={spp}"]
        return cmd
    for name, value in (("res", RES), ("spp", spp), ("max_depth", scene.max_depth)):
        if name in scene.defaults:
            cmd += ["-D", f"{name}={value}"]
    # Scenes without an <integrator> (the externals) get max_depth/rr_depth on the command line.
    if not scene.has_integrator or "max_depth" not in scene.defaults:
        if "--max-depth" in help_text:
            cmd += ["--max-depth", str(scene.max_depth)]
        elif scene.max_depth >= 0:
            print(f"  warning: render has no --max-depth; {scene.name} needs max_depth {scene.max_depth}",
                  file=sys.stderr)
    if "--rr-depth" in help_text:
        cmd += ["--rr-depth", str(scene.rr_depth)]
    return cmd


def tonemap(img, exposure):
    """Linear -> 8-bit sRGB."""
    x = np.clip(img * exposure, 0.0, 1.0)
    x = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return (x * 255.0 + 0.5).astype(np.uint8)


def diff_heatmap(ours_d, ref_d, scale=0.2):
    """Relative difference of the downsampled images as colours (red: ours brighter)."""
    lum_o, lum_r = ours_d.mean(axis=2), ref_d.mean(axis=2)
    rel = np.clip((lum_o - lum_r) / (lum_r + 0.05) / scale, -1.0, 1.0)
    rgb = np.ones(rel.shape + (3,))
    rgb[..., 1] = 1.0 - np.abs(rel)
    rgb[..., 0] = np.where(rel < 0, 1.0 + rel, 1.0)
    rgb[..., 2] = np.where(rel > 0, 1.0 - rel, 1.0)
    big = np.repeat(np.repeat(rgb, DOWN, axis=0), DOWN, axis=1)
    return (big * 255.0 + 0.5).astype(np.uint8)


def side_by_side(path, ref, ours, exposure):
    mi = mitsuba()
    gap = np.full((ref.shape[0], 4, 3), 255, np.uint8)
    row = np.concatenate([tonemap(ref, exposure), gap, tonemap(ours, exposure), gap,
                          diff_heatmap(downsample(ours), downsample(ref))], axis=1)
    mi.Bitmap(row, mi.Bitmap.PixelFormat.RGB).write(str(path))


def compare(ours, ref, ref_chunks, spp_ours, spp_ref):
    """relMSE after downsampling, per-channel mean difference, and the noise-only relMSE."""
    a, b = downsample(ours), downsample(ref)
    denom = b * b + 1e-2
    rel_mse = float(np.mean((a - b) ** 2 / denom))
    mean_a, mean_b = ours.mean(axis=(0, 1)), ref.mean(axis=(0, 1))
    mean_rel = (mean_a - mean_b) / np.maximum(mean_b, 1e-8)
    n = ref_chunks.shape[0]
    if n > 1:
        var_ref = ref_chunks.astype(np.float64).var(axis=0, ddof=1) / n  # variance of the mean
        var_ours = var_ref * spp_ref / spp_ours  # same per-sample variance assumed
        noise = float(np.mean((var_ref + var_ours) / denom))
    else:
        noise = float("nan")
    return rel_mse, mean_a, mean_b, mean_rel, noise


def fmt_rgb(v):
    return ", ".join(f"{x:.4f}" for x in v)


def update_doc(doc, table, command):
    text = doc.read_text() if doc.exists() else ""
    block = f"{DOC_BEGIN}\nCommand: `{command}`\n\n{table}\n{DOC_END}"
    if DOC_BEGIN in text and DOC_END in text:
        text = text[: text.index(DOC_BEGIN)] + block + text[text.index(DOC_END) + len(DOC_END):]
    else:
        text = text.rstrip() + "\n\n" + block + "\n"
    tmp = doc.with_suffix(".tmp")
    tmp.write_text(text)
    os.replace(tmp, doc)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", help="comma-separated scene names (default: all)")
    ap.add_argument("--scene-root", type=Path, help="validate DIR/*/scene.xml (e.g. datagen scenes) instead")
    ap.add_argument("--spp", type=int, default=4096, help="our samples per pixel (default 4096)")
    ap.add_argument("--ref-spp", type=int, default=4096, help="Mitsuba samples per pixel (default 4096)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--threads", type=int, default=0, help="render --threads (0: its default)")
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "validation")
    ap.add_argument("--bin", type=Path, default=ROOT / "target" / "release" / "render")
    ap.add_argument("--no-build", action="store_true", help="do not run cargo build first")
    ap.add_argument("--refs-only", action="store_true", help="only render/cache Mitsuba references")
    ap.add_argument("--force-refs", action="store_true", help="re-render cached references")
    ap.add_argument("--reuse-ours", action="store_true", help="compare existing ours.exr, do not render")
    ap.add_argument("--doc", type=Path, help="write the table into this markdown file")
    args = ap.parse_args()

    scenes = discover(args.scenes, args.scene_root)
    if not args.refs_only and not args.reuse_ours and not args.no_build:
        subprocess.run(["cargo", "build", "--release", "-p", "renderer", "--bin", "render"], cwd=ROOT, check=True)
    help_text = "" if args.refs_only or args.reuse_ours else render_help(args.bin)

    rows, failures = [], 0
    for scene in scenes:
        out_dir = args.out / scene.name
        if not scene.path_traceable:
            rows.append(f"| {scene.name} | {scene.group} | – | – | – | – | – | – | not compared: "
                        f"reference is `{scene.meta.get('integrator')}` (SPPM-only scene, see its README) |")
            continue
        print(f"== {scene.name}", file=sys.stderr, flush=True)
        ref, ref_chunks, info = mitsuba_reference(scene, args.ref_spp, out_dir, args.force_refs)
        if scene.group == "external" and (scene.xml.parent / "reference.exr").exists():
            shared = read_exr(scene.xml.parent / "reference.exr")
            r, _, _, mr, _ = compare(ref, shared, ref_chunks[:1], args.ref_spp, args.ref_spp)
            print(f"  our Mitsuba reference vs shared reference.exr: relMSE {r:.2e}, "
                  f"mean diff {fmt_rgb(100 * mr)} %", file=sys.stderr)
        if args.refs_only:
            continue
        ours_exr, ours_png = out_dir / "ours.exr", out_dir / "ours.png"
        seconds = float("nan")
        if not args.reuse_ours:
            cmd = ours_command(scene, args.bin, help_text, args.spp, args.seed, ours_exr, ours_png, args.threads)
            print("  " + " ".join(shlex.quote(c) for c in cmd), file=sys.stderr, flush=True)
            t0 = time.time()
            proc = subprocess.run(cmd, cwd=ROOT)
            seconds = time.time() - t0
            if proc.returncode != 0:
                failures += 1
                rows.append(f"| {scene.name} | {scene.group} | {scene.depth_label} | – | – | – | – | – | "
                            f"FAIL: render exited with {proc.returncode} |")
                continue
        ours = read_exr(ours_exr)
        if ours.shape != ref.shape:
            failures += 1
            rows.append(f"| {scene.name} | {scene.group} | {scene.depth_label} | – | – | – | – | – | "
                        f"FAIL: image {ours.shape[1]}x{ours.shape[0]}, Mitsuba's {ref.shape[1]}x{ref.shape[0]} |")
            continue
        rel_mse, mean_a, mean_b, mean_rel, noise = compare(ours, ref, ref_chunks, args.spp, args.ref_spp)
        ok = rel_mse <= REL_MSE_MAX and np.all(np.abs(mean_rel) <= MEAN_TOL)
        failures += 0 if ok else 1
        exposure = scene.meta.get("png_exposure") or 0.8 / max(np.percentile(ref.mean(axis=2), 99), 1e-6)
        side_by_side(out_dir / "side_by_side.png", ref, ours, exposure)
        (out_dir / "result.json").write_text(json.dumps(dict(
            rel_mse=rel_mse, noise_floor=noise, mean_ours=list(map(float, mean_a)),
            mean_mitsuba=list(map(float, mean_b)), mean_rel=list(map(float, mean_rel)),
            ok=bool(ok), spp=args.spp, ref_spp=args.ref_spp, seconds_ours=seconds,
            seconds_mitsuba=info.get("seconds")), indent=2) + "\n")
        rows.append(f"| {scene.name} | {scene.group} | {scene.depth_label} | {rel_mse:.2e} | {noise:.1e} | "
                    f"{fmt_rgb(mean_b)} | {fmt_rgb(mean_a)} | {', '.join(f'{100 * x:+.2f}' for x in mean_rel)} | "
                    f"{'pass' if ok else 'FAIL'} |")
        print(rows[-1], file=sys.stderr, flush=True)

    if args.refs_only:
        return 0
    table = (f"Path tracer vs Mitsuba 3 `path` (llvm_ad_rgb), {RES} pixels wide (square unless the scene "
             f"sets its height), box filter; ours {args.spp} spp "
             f"(seed {args.seed}), Mitsuba {args.ref_spp} spp. relMSE after {DOWN}x{DOWN} box downsampling, "
             f"threshold {REL_MSE_MAX:.0e}; mean RGB within {100 * MEAN_TOL:.0f} %. "
             "Noise floor: the relMSE that noise alone would give (estimated from Mitsuba's chunks).\n\n"
             "| scene | set | max_depth | relMSE | noise floor | mean RGB Mitsuba | mean RGB ours | "
             "mean diff % (R, G, B) | result |\n|---|---|---|---|---|---|---|---|---|\n" + "\n".join(rows) + "\n")
    print(table)
    if args.doc:
        command = "python3 scripts/validate_pt.py" + "".join(
            f" {a}" for a in sys.argv[1:] if not a.startswith("--doc") and a != str(args.doc))
        update_doc(args.doc, table, command)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
