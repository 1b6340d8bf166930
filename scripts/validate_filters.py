#!/usr/bin/env python3
"""Validate the reconstruction filters (`<rfilter>`) against Mitsuba 3, pixel by pixel.

Mitsuba splats each sample into the pixels around it with the filter's weights; our renderer
draws each pixel's samples from the filter centred on it (filter importance sampling,
renderer/src/filter.rs). Both converge to the same image. Downsampled comparisons (as
validate_pt.py makes) would hide the difference between filters, so this script compares at
full resolution, on scenes/validation/default-filter (sharp high-contrast edges, no <rfilter>
in the file: Mitsuba's default Gaussian), once per filter:

1. writes a variant of the scene with the filter inserted into its film
   (out/validation-filters/<variant>/scene.xml);
2. renders it with Mitsuba 3 (`path`, llvm_ad_rgb, 128x128, chunks of distinct seeds) and
   with our `render --integrator path` at the same spp;
3. reports, without downsampling,
       relMSE(ours, Mitsuba) = mean((ours - mitsuba)^2 / (mitsuba^2 + 1e-2))
   next to the noise floor (what noise alone explains: the variance of both images, each from
   the spread of its chunks rendered with distinct seeds) and next to relMSE(ours with the box
   filter, Mitsuba with this filter): the error a renderer that ignored the filter would show.
   Pass: relMSE <= 1.25 x noise floor (no error beyond noise), and the box filter's error at
   least 3 x the floor (the comparison can see a wrong filter).

Mitsuba is a development tool only (`pip install mitsuba`).

    python3 scripts/validate_filters.py                     # 4096 spp, every filter
    python3 scripts/validate_filters.py --spp 1024 --filters default,lanczos
"""

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import validate_pt as vp  # noqa: E402

ROOT = vp.ROOT
SCENE = ROOT / "scenes" / "validation" / "default-filter" / "scene.xml"
CHUNK_SPP = 512

# name -> the <rfilter> inserted into the film ("" = none: Mitsuba's default Gaussian).
VARIANTS = {
    "default": "",
    "box": '<rfilter type="box"/>',
    "gaussian-0.3": '<rfilter type="gaussian"><float name="stddev" value="0.3"/></rfilter>',
    "tent": '<rfilter type="tent"/>',
    "tent-1.5": '<rfilter type="tent"><float name="radius" value="1.5"/></rfilter>',
    "mitchell": '<rfilter type="mitchell"/>',
    "catmullrom": '<rfilter type="catmullrom"/>',
    "lanczos": '<rfilter type="lanczos"/>',
    "lanczos-2": '<rfilter type="lanczos"><integer name="lobes" value="2"/></rfilter>',
}


def variant_scene(name, out):
    """Writes the scene with this variant's filter; returns a validate_pt.Scene for it."""
    text = SCENE.read_text()
    if "<rfilter type" in text or text.count("</film>") != 1:
        sys.exit(f"{SCENE}: expected one <film> without <rfilter>")
    text = text.replace("</film>", VARIANTS[name] + "</film>")
    path = out / name / "scene.xml"
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)
    return vp.Scene(name, path, "filters")


def mitsuba_render(scene, spp, out_dir):
    """Mitsuba's image and its chunks (full resolution), cached by the scene's hash."""
    settings = {"spp": spp, "chunk_spp": CHUNK_SPP, "res": vp.RES, "max_depth": scene.max_depth}
    key = scene.files_hash(settings)
    exr, npy, info_path = out_dir / "mitsuba.exr", out_dir / "mitsuba_chunks.npy", out_dir / "mitsuba.json"
    if info_path.exists() and exr.exists() and npy.exists():
        if json.loads(info_path.read_text()).get("key") == key:
            return vp.read_exr(exr), np.load(npy)
    mi = vp.mitsuba()
    mi.set_variant("llvm_ad_rgb")
    chunks = max(1, spp // CHUNK_SPP)
    sc = mi.load_file(str(scene.xml), **scene.load_params(spp // chunks))
    integrator = mi.load_dict({"type": "path", "max_depth": scene.max_depth})
    t0 = time.time()
    imgs = []
    for k in range(chunks):
        img = mi.render(sc, integrator=integrator, spp=spp // chunks, seed=7000 + k)
        imgs.append(np.array(img, dtype=np.float64)[..., :3])
    stack = np.stack(imgs)
    img = stack.mean(axis=0)
    vp.write_exr(exr, img)
    np.save(npy, stack.astype(np.float32))
    info = dict(settings, key=key, seconds=round(time.time() - t0, 1), mitsuba=mi.__version__)
    info_path.write_text(json.dumps(info, indent=2) + "\n")
    return img, stack


def rel_mse(a, b):
    return float(np.mean((a - b) ** 2 / (b * b + 1e-2)))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--filters", help="comma-separated variants (default: all): " + ", ".join(VARIANTS))
    ap.add_argument("--spp", type=int, default=4096)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "validation-filters")
    ap.add_argument("--bin", type=Path, default=ROOT / "target" / "release" / "render")
    args = ap.parse_args()
    names = args.filters.split(",") if args.filters else list(VARIANTS)
    unknown = set(names) - set(VARIANTS)
    if unknown:
        sys.exit(f"unknown filter variant(s): {', '.join(sorted(unknown))}")
    if not args.bin.exists():
        sys.exit(f"{args.bin}: no such binary (cargo build --release -p renderer --bin render)")
    help_text = vp.render_help(args.bin)

    def ours(scene, out_dir, tag):
        """Our image (mean of chunks with distinct seeds) and its chunks, as Mitsuba's."""
        chunks = max(1, args.spp // CHUNK_SPP)
        imgs = []
        for k in range(chunks):
            exr = out_dir / f"ours-{tag}-{k}.exr"
            cmd = vp.ours_command(scene, args.bin, help_text, args.spp // chunks, args.seed + k, exr,
                                  out_dir / f"ours-{tag}.png", 0)
            subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            imgs.append(vp.read_exr(exr))
            exr.unlink()
        stack = np.stack(imgs)
        img = stack.mean(axis=0)
        vp.write_exr(out_dir / f"ours-{tag}.exr", img)
        return img, stack

    box_scene = variant_scene("box", args.out)
    ours_box, ours_box_chunks = ours(box_scene, args.out / "box", "box")
    rows, failures = [], 0
    for name in names:
        scene = variant_scene(name, args.out)
        out_dir = args.out / name
        ref, chunks = mitsuba_render(scene, args.spp, out_dir)
        img, img_chunks = (ours_box, ours_box_chunks) if name == "box" else ours(scene, out_dir, name)
        # Noise floor: the variance of both means, each from the spread of its own chunks
        # (Mitsuba's splatting shares every sample between pixels, so its noise is lower).
        var = sum(c.astype(np.float64).var(axis=0, ddof=1) / c.shape[0] for c in (chunks, img_chunks))
        noise = float(np.mean(var / (ref * ref + 1e-2)))
        err = rel_mse(img, ref)
        err_box = rel_mse(ours_box, ref)
        # Unbiased images differ by noise alone: E[relMSE] = the noise floor. The comparison
        # must also be able to see a wrong filter: the box's error well above the floor.
        ok = err <= 1.25 * noise and (name == "box" or err_box >= 3 * noise)
        failures += not ok
        mean_rel = (img.mean(axis=(0, 1)) / ref.mean(axis=(0, 1)) - 1) * 100
        rows.append(f"| {name} | {VARIANTS[name] or '(none: Gaussian, stddev 0.5)'} | {err:.2e} | "
                    f"{noise:.2e} | {'–' if name == 'box' else f'{err_box:.2e}'} | "
                    f"{', '.join(f'{m:+.2f}' for m in mean_rel)} % | {'pass' if ok else 'FAIL'} |")
        print(rows[-1], flush=True)
    print()
    print("| filter | `<rfilter>` in the film | relMSE ours vs Mitsuba (full resolution) | noise floor "
          "| relMSE if ours used the box filter | mean RGB ours / Mitsuba − 1 | result |")
    print("|---|---|---|---|---|---|---|")
    print("\n".join(rows))
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
