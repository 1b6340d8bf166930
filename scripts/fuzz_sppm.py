#!/usr/bin/env python3
"""Consistency test of multi-level SPPM against our path tracer on random scenes.

The scenes are those of `fuzz_mitsuba.py` (every BSDF plugin with random parameters, five
shape types), chosen so that the path tracer converges everywhere: by default lit by area
lights and a constant sky only; with `--delta-lights`, lit by every light type (point, spot and
directional too) but without smooth (delta) materials, since a delta light seen through glass
makes caustics only photons carry. Each scene is rendered at 32x32 by

* the path tracer: unbounded depth (Russian roulette), `--spp` samples per pixel in 4 runs of
  different seeds (their spread gives the noise), and
* `render --integrator sppm-ml`: `--photons` per pass, `--passes` passes, max_depth 24.

A scene is flagged when the image mean of any level (y, z1..z4) differs from the path tracer's
by more than max(5 sigma, --tol) in any channel (sigma from the path tracer's run-to-run spread
and the bundle's stored variances). The worst 8x8-pixel block of the sharpest
level is printed too, for a look (kernel bias at edges makes it larger than the image mean's).
Flagged scenes keep their XML and images under out/fuzz-sppm/<seed>/. `--hide-emitters` sets
the scenes' `hide_emitters` (both renderers read it from the file); `--extended` draws the scenes
from fuzz_mitsuba.py's extended generator (textures, normal and bump maps, meshes, instances,
envmaps, other cameras and filters) under the same rules.

    python3 scripts/fuzz_sppm.py --count 40 --seed 1 --bin target/release/render
"""

import shutil
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from fuzz_mitsuba import (  # noqa: E402
    CHUNKS, EXTRA_MATERIALS, finish, fuzz_arguments, integrator_variant, render_path_chunks, run_render, scene_dirs,
    scene_xml)
from validate_pt import mitsuba  # noqa: E402

LEVELS = ["y", "z1", "z2", "z3", "z4"]


def read_levels(path):
    """The five levels of a bundle as (H, W, 3) float64 arrays, and their stored variances
    (of each pixel's mean, averaged over RGB) as (H, W) arrays."""
    mi = mitsuba()
    mi.set_variant("scalar_rgb")
    b = mi.Bitmap(str(path))
    names = [f.name for f in b.struct_()]
    a = np.array(b, dtype=np.float64)
    levels = {l: np.stack([a[..., names.index(f"{l}.{c}")] for c in "RGB"], axis=-1) for l in LEVELS}
    variances = {l: a[..., names.index(f"variance.{l}")] for l in LEVELS}
    return levels, variances


def main():
    ap = fuzz_arguments(__doc__.split("\n")[0], 4096, "path tracer samples per pixel", "fuzz-sppm")
    ap.add_argument("--photons", type=int, default=50_000, help="SPPM photons per pass")
    ap.add_argument("--passes", type=int, default=512, help="SPPM passes")
    ap.add_argument("--tol", type=float, default=0.02, help="relative tolerance of the image mean")
    ap.add_argument("--delta-lights", action="store_true",
                    help="every light type, no smooth materials (default: area lights and sky)")
    ap.add_argument("--hide-emitters", action="store_true", help="set the scenes' hide_emitters")
    ap.add_argument("--extended", action="store_true",
                    help="the scenes of fuzz_mitsuba.py --extended (scripts/fuzz_extended.py)")
    ap.add_argument("--thin", action="store_true",
                    help="the thin principled BSDF among the materials (as fuzz_mitsuba.py --thin)")
    args = ap.parse_args()
    if args.thin:
        EXTRA_MATERIALS.extend(["principledthin"] * 3)
    out = Path(args.out) / str(args.seed)
    out.mkdir(parents=True, exist_ok=True)
    flagged, rows = [], []
    for index, d, xml in scene_dirs(args):
        make = scene_xml
        if args.extended:
            from fuzz_extended import extended_scene_xml
            make = lambda *a, **k: extended_scene_xml(*a[:2], d, **k)  # noqa: E731
        if args.delta_lights:
            text = make(args.seed, index, lights="all", delta_materials=False)
        else:
            text = make(args.seed, index, lights="area")
        if args.hide_emitters:
            text = integrator_variant(text, args.seed, index, direct=False, hide=True)[0]
        xml.write_text(text)
        try:
            chunks = render_path_chunks(args.bin, xml, args.spp, d, "path", "--max-depth", -1)
            run_render([args.bin, xml, "--integrator", "sppm-ml", "--photons", args.photons, "--passes",
                 args.passes, "--max-depth", 24, "--seed", 7, "--out", d / "sppm"])
            levels, variances = read_levels(d / f"sppm_p{args.passes:04d}.exr")
        except RuntimeError as e:
            flagged.append(index)
            rows.append({"index": index, "error": str(e)})
            print(f"{index:4d}: failed: {e}", flush=True)
            continue
        ref = chunks.mean(axis=0)
        ref_mean = ref.mean(axis=(0, 1))
        var_path = chunks.mean(axis=(1, 2)).var(axis=0, ddof=1) / CHUNKS
        # The image mean's variance from the stored per-pixel variances, pixels taken as
        # independent (their shared photons correlate them: a lower bound).
        n_pixels = ref.shape[0] * ref.shape[1]
        var_sppm = {l: float(variances[l].sum()) / n_pixels**2 for l in LEVELS}
        tol = {l: np.maximum(5 * np.sqrt(var_path + var_sppm[l]), args.tol * np.abs(ref_mean))
               for l in LEVELS}
        rel = {l: ((levels[l].mean(axis=(0, 1)) - ref_mean) / np.maximum(ref_mean, 1e-8)).tolist()
               for l in LEVELS}
        bad = [l for l in LEVELS if np.any(np.abs(levels[l].mean(axis=(0, 1)) - ref_mean) > tol[l])]
        h, w, _ = ref.shape
        blocks = lambda img: img[: h - h % 8, : w - w % 8].reshape(h // 8, 8, w // 8, 8, 3).mean(axis=(1, 3))
        worst = float(np.max(np.abs(blocks(levels["y"]) - blocks(ref)) / (blocks(ref) + 1e-2)))
        row = {"index": index, "mean_rel": rel, "worst_block_rel_y": worst, "flag": bool(bad)}
        rows.append(row)
        print(f"{index:4d}: {'FLAG' if bad else 'ok':4s} mean rel diff y {np.mean(rel['y']):+.2%} "
              f"z2 {np.mean(rel['z2']):+.2%} z4 {np.mean(rel['z4']):+.2%}; worst 8x8 block of y "
              f"{worst:.1%}" + (f"; off: {', '.join(bad)}" if bad else ""), flush=True)
        if bad:
            flagged.append(index)
        elif not args.keep:
            shutil.rmtree(d)
    finish(out, rows, flagged, args.count)


if __name__ == "__main__":
    main()
