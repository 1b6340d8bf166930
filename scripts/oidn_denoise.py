#!/usr/bin/env python3
"""Intel Open Image Denoise on one HDR image: the development-side peer `evaluate` calls for its
"SPPM + OIDN" and "path tracing + OIDN" columns (docs/evaluation.md, "Peers").

Never a runtime dependency of the toolkit: `pip install pyoidn==2.5.1.0` (OIDN 2.5) where the
peers are wanted.

Images travel as raw little-endian float32, interleaved RGB, rows top to bottom (W*H*3 values):
color (linear HDR radiance), albedo ([0, 1]) and normal ([-1, 1]) in, the denoised color out.
The filter is OIDN's `RT` filter with `hdr=True`, quality `high`, noisy auxiliary images
(OIDN prefilters them). The time reported is the median of `--repeats` timed calls after one
warm-up call (which also creates the device): the steady-state cost a renderer pays per image.

Prints one JSON line: {"seconds": median, "first_seconds": warm-up call, "all_seconds": [...],
"oidn": version}. `--version` prints the pyoidn version and exits (0 when it is importable).
"""

import argparse
import json
import sys
import time


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--version", action="store_true", help="print the pyoidn version and exit")
    p.add_argument("--width", type=int)
    p.add_argument("--height", type=int)
    p.add_argument("--color", help="noisy HDR color, raw f32 RGB")
    p.add_argument("--albedo", help="albedo, raw f32 RGB (optional)")
    p.add_argument("--normal", help="normal, raw f32 RGB (optional; needs --albedo)")
    p.add_argument("--output", help="denoised color, raw f32 RGB")
    p.add_argument("--repeats", type=int, default=3, help="timed calls after the warm-up")
    a = p.parse_args()
    try:
        import numpy as np
        import pyoidn
    except ImportError as e:
        sys.exit(f"oidn_denoise.py: {e}: install the peer with `pip install pyoidn==2.5.1.0`")
    version = getattr(pyoidn, "__version__", None) or _dist_version()
    if a.version:
        print(version)
        return
    for name in ("width", "height", "color", "output"):
        if getattr(a, name) is None:
            sys.exit(f"oidn_denoise.py: --{name} is required")
    if a.normal and not a.albedo:
        sys.exit("oidn_denoise.py: --normal needs --albedo (OIDN's rule)")
    if a.width <= 0 or a.height <= 0 or a.repeats < 1:
        sys.exit("oidn_denoise.py: --width, --height and --repeats must be positive")
    shape = (a.height, a.width, 3)

    def load(path, what):
        data = np.fromfile(path, dtype="<f4")
        if data.size != a.width * a.height * 3:
            sys.exit(f"oidn_denoise.py: {path} ({what}): {data.size} values, expected "
                     f"{a.width}x{a.height}x3 = {a.width * a.height * 3}")
        if not np.all(np.isfinite(data)):
            sys.exit(f"oidn_denoise.py: {path} ({what}): holds NaN or Inf")
        return np.ascontiguousarray(data.reshape(shape))

    color = np.maximum(load(a.color, "color"), 0.0)
    albedo = np.clip(load(a.albedo, "albedo"), 0.0, 1.0) if a.albedo else None
    normal = np.clip(load(a.normal, "normal"), -1.0, 1.0) if a.normal else None

    def run():
        t = time.perf_counter()
        out = pyoidn.denoise(color, albedo, normal, hdr=True, quality="high")
        return out, time.perf_counter() - t

    out, first = run()
    times = []
    for _ in range(a.repeats):
        out, s = run()
        times.append(s)
    np.ascontiguousarray(out, dtype="<f4").tofile(a.output)
    times_sorted = sorted(times)
    print(json.dumps({
        "seconds": times_sorted[len(times_sorted) // 2],
        "first_seconds": first,
        "all_seconds": times,
        "oidn": version,
    }))


def _dist_version():
    try:
        from importlib.metadata import version
        return version("pyoidn")
    except Exception:
        return "unknown"


if __name__ == "__main__":
    main()
