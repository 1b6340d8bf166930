#!/usr/bin/env python3
"""Path-tracing throughput: Mitsuba 3 next to our `render`, in the same invocation (issue 2,
"Must show 3").

Scene: Mitsuba's Cornell box (../shared/scenes/external/cbox/scene.xml, the XML of
`mi.cornell_box()`'s data companion) at 256x256, `path` with max_depth 8 (rr_depth 5, Mitsuba's
default), box filter. Samples/s = width * height * spp / seconds of rendering.

* Mitsuba `llvm_ad_rgb` and `scalar_rgb` (all cores): one warm-up render (JIT compilation,
  thread pool), then the best of --repeats timed renders; scene loading is not timed.
* ours: `render --integrator path` at --threads 1 and at all cores (default: 1 and 2), wall
  clock of the whole process (scene load + BVH build included, so it is a conservative number)
  unless the renderer prints a "samples/s" figure, which is then reported next to it.

Prints a markdown table and the ratios ours / Mitsuba and ours(N threads) / ours(1 thread).

    python3 scripts/bench_mitsuba.py                      # Mitsuba + ours
    python3 scripts/bench_mitsuba.py --mitsuba-only
    python3 scripts/bench_mitsuba.py --ours-spp 256 --threads 1,2 --json out/bench.json

`--scene`, `--integrator` (`path` or `volpath`), `--res` and `--max-depth` time another scene
(it needs a `res` default), e.g. participating media against Mitsuba's `volpath`:

    python3 scripts/bench_mitsuba.py --scene scenes/validation/media-camera/scene.xml \
        --integrator volpath --res 128 --max-depth 10 --llvm-spp 512 --scalar-spp 64 --ours-spp 512
"""

import argparse
import json
import os
import re
import resource
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CBOX = (ROOT / ".." / "shared" / "scenes" / "external" / "cbox" / "scene.xml").resolve()
RES = 256
MAX_DEPTH = 8


def bench_mitsuba(variant, spp, repeats, scene=str(CBOX), kind="path", res=RES, max_depth=MAX_DEPTH):
    """Best-of-`repeats` samples/s of Mitsuba's integrator `kind` in `variant`."""
    import drjit as dr
    import mitsuba as mi

    mi.set_variant(variant)
    scene = mi.load_file(str(scene), res=res, spp=spp)
    integrator = mi.load_dict({"type": kind, "max_depth": max_depth})
    warm = mi.render(scene, integrator=integrator, spp=spp, seed=0)
    dr.eval(warm)
    dr.sync_thread()
    best, best_cpu = float("inf"), float("inf")
    for k in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        img = mi.render(scene, integrator=integrator, spp=spp, seed=1 + k)
        dr.eval(img)
        dr.sync_thread()
        _ = img.numpy() if hasattr(img, "numpy") else img
        best = min(best, time.perf_counter() - t0)
        best_cpu = min(best_cpu, time.process_time() - c0)
    return res * res * spp / best, best, best_cpu


def bench_ours(binary, spp, threads, out_dir, scene=CBOX, kind="path", res=RES, max_depth=MAX_DEPTH):
    """Samples/s of our integrator `kind` on the same scene (wall clock of the process)."""
    help_text = subprocess.run([str(binary), "--help"], capture_output=True, text=True).stdout
    out = out_dir / f"bench_ours_t{threads}.exr"
    cmd = [str(binary), str(scene), "--integrator", kind, "--spp", str(spp), "--seed", "1",
           "--out", str(out), "--threads", str(threads), "-D", f"res={res}", "-D", f"spp={spp}"]
    if "--max-depth" in help_text:
        cmd += ["--max-depth", str(max_depth)]
    else:
        sys.exit(f"render has no --max-depth option: cannot set max_depth {max_depth}")
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    if proc.returncode != 0:
        sys.exit(f"render failed ({proc.returncode}):\n{proc.stderr[-2000:]}")
    # Prefer the renderer's own figure when it prints one (rendering only, no scene load).
    reported = None
    for line in (proc.stdout + proc.stderr).splitlines()[::-1]:
        m = re.search(r"([0-9.]+)\s*([kMG]?)\s*samples/s", line)
        if m:
            reported = float(m.group(1)) * {"": 1, "k": 1e3, "M": 1e6, "G": 1e9}[m.group(2)]
            break
    return res * res * spp / wall, wall, reported, cmd, cpu


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--llvm-spp", type=int, default=256)
    ap.add_argument("--scalar-spp", type=int, default=32)
    ap.add_argument("--ours-spp", type=int, default=256)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--threads", default=f"1,{os.cpu_count()}", help="our thread counts, e.g. 1,2")
    ap.add_argument("--bin", type=Path, default=ROOT / "target" / "release" / "render")
    ap.add_argument("--no-build", action="store_true")
    ap.add_argument("--mitsuba-only", action="store_true")
    ap.add_argument("--ours-only", action="store_true")
    ap.add_argument("--json", type=Path, help="also write the numbers as JSON")
    ap.add_argument("--out-dir", type=Path, default=ROOT / "out" / "bench",
                    help="folder for our rendered images (default out/bench)")
    ap.add_argument("--scene", type=Path, default=CBOX, help="scene file (default: Mitsuba's Cornell box)")
    ap.add_argument("--integrator", choices=["path", "volpath"], default="path")
    ap.add_argument("--res", type=int, default=RES, help="image side (the scene's `res` default)")
    ap.add_argument("--max-depth", type=int, default=MAX_DEPTH)
    args = ap.parse_args()
    scene, kind, res, max_depth = args.scene.resolve(), args.integrator, args.res, args.max_depth

    rows, results = [], {"scene": str(scene), "integrator": kind, "res": res, "max_depth": max_depth,
                         "cpus": os.cpu_count()}
    if not args.ours_only:
        # Run each variant in its own process: drjit's LLVM backend and the scalar variant then
        # do not share a thread pool or JIT caches, and each starts cold as a user would.
        for variant, spp in (("llvm_ad_rgb", args.llvm_spp), ("scalar_rgb", args.scalar_spp)):
            code = ("import sys, json; sys.path.insert(0, %r); import bench_mitsuba as b; "
                    "print(json.dumps(b.bench_mitsuba(%r, %d, %d, %r, %r, %d, %d)))"
                    % (str(Path(__file__).parent), variant, spp, args.repeats, str(scene), kind, res,
                       max_depth))
            proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
            if proc.returncode != 0:
                sys.exit(f"Mitsuba {variant} failed:\n{proc.stderr[-2000:]}")
            sps, sec, cpu = json.loads(proc.stdout.strip().splitlines()[-1])
            results[f"mitsuba_{variant}"] = {"samples_per_s": sps, "seconds": sec, "cpu_seconds": cpu,
                                             "spp": spp}
            rows.append((f"Mitsuba 3 `{variant}` (all cores)", spp, sec, sps, None, cpu))
    if not args.mitsuba_only:
        if not args.no_build:
            subprocess.run(["cargo", "build", "--release", "-p", "renderer", "--bin", "render"], cwd=ROOT,
                           check=True)
        out_dir = args.out_dir
        out_dir.mkdir(parents=True, exist_ok=True)
        for t in [int(x) for x in args.threads.split(",")]:
            sps, wall, reported, cmd, cpu = bench_ours(args.bin, args.ours_spp, t, out_dir, scene, kind, res,
                                                       max_depth)
            results[f"ours_t{t}"] = {"samples_per_s_wall": sps, "seconds_wall": wall, "cpu_seconds": cpu,
                                     "samples_per_s_reported": reported, "spp": args.ours_spp,
                                     "command": " ".join(cmd)}
            rows.append((f"ours `render --integrator {kind} --threads {t}`", args.ours_spp, wall, sps, reported,
                         cpu))

    load = os.getloadavg()
    print(f"{kind}, {scene.parent.name} {res}x{res}, max_depth {max_depth}, {os.cpu_count()} CPUs, "
          f"load average {load[0]:.1f} {load[1]:.1f} {load[2]:.1f}\n")
    print("CPU: process CPU seconds of the timed part (ours: the whole process, scene load included);")
    print("samples per CPU-second is what each renderer gets out of a core, whatever else the machine runs.\n")
    print("| renderer | spp | seconds | samples/s (wall) | samples/s (reported) | CPU s | samples per CPU-s |")
    print("|---|---|---|---|---|---|---|")
    for name, spp, sec, sps, rep, cpu in rows:
        rep_s = f"{rep / 1e6:.3f} M" if rep else "–"
        per_cpu = f"{res * res * spp / cpu / 1e6:.3f} M" if cpu > 0 else "–"
        print(f"| {name} | {spp} | {sec:.2f} | {sps / 1e6:.3f} M | {rep_s} | {cpu:.2f} | {per_cpu} |")
    llvm = results.get("mitsuba_llvm_ad_rgb", {}).get("samples_per_s")
    scalar = results.get("mitsuba_scalar_rgb", {}).get("samples_per_s")
    ours = {k: v["samples_per_s_wall"] for k, v in results.items() if k.startswith("ours_t")}
    print()
    for k, v in ours.items():
        if llvm:
            print(f"{k} / Mitsuba llvm_ad_rgb = {v / llvm:.2f}x")
        if scalar:
            print(f"{k} / Mitsuba scalar_rgb = {v / scalar:.2f}x")
    per_cpu = {k: res * res * v["spp"] / v["cpu_seconds"] for k, v in results.items()
               if isinstance(v, dict) and v.get("cpu_seconds")}
    for k, v in per_cpu.items():
        for m in ("mitsuba_llvm_ad_rgb", "mitsuba_scalar_rgb"):
            if k.startswith("ours_t") and m in per_cpu:
                print(f"{k} / {m}, samples per CPU-second = {v / per_cpu[m]:.2f}x")
    if "ours_t1" in ours and len(ours) > 1:
        for k, v in ours.items():
            if k != "ours_t1":
                print(f"{k} / ours_t1 = {v / ours['ours_t1']:.2f}x")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    main()
