#!/usr/bin/env python3
"""Writes the voxel grids of the `media-grid` validation scene (run from this folder; numpy):

* density.vol: 32^3, one channel, a smoke-like plume (three Gaussian puffs with a fixed-seed
  value-noise modulation), 0 at the grid's border, maximum 1;
* albedo.vol: 4^3, three channels, a colour gradient (bluish at the bottom, warm at the top).

Format: Mitsuba's .vol (docs/formats.md): "VOL", version 3, encoding 1 (float32), resolution,
channels, bounding box, values with x fastest, then y, then z, channels innermost.
"""
import struct

import numpy as np


def write_vol(path, data):
    z, y, x, c = data.shape
    with open(path, "wb") as f:
        f.write(b"VOL" + bytes([3]))
        f.write(struct.pack("<iiiii", 1, x, y, z, c))
        f.write(struct.pack("<6f", 0, 0, 0, 1, 1, 1))
        f.write(np.ascontiguousarray(data, dtype="<f4").tobytes())


n = 32
c = (np.arange(n) + 0.5) / n
zz, yy, xx = np.meshgrid(c, c, c, indexing="ij")
density = np.zeros((n, n, n))
for (px, py, pz, r, w) in [(0.5, 0.3, 0.5, 0.22, 1.0), (0.42, 0.58, 0.55, 0.17, 0.8), (0.6, 0.75, 0.45, 0.12, 0.6)]:
    density += w * np.exp(-((xx - px) ** 2 + (yy - py) ** 2 + (zz - pz) ** 2) / (2 * r * r))
rng = np.random.default_rng(7)
coarse = rng.uniform(0.6, 1.4, (5, 5, 5))
idx = np.clip((np.stack([zz, yy, xx]) * 4).astype(int), 0, 4)
density *= coarse[idx[0], idx[1], idx[2]]
density[[0, -1], :, :] = 0
density[:, [0, -1], :] = 0
density[:, :, [0, -1]] = 0
density /= density.max()
write_vol("density.vol", density[..., None])

m = 4
t = (np.arange(m) + 0.5) / m
albedo = np.zeros((m, m, m, 3))
for j in range(m):  # along y
    albedo[:, j, :, :] = (1 - t[j]) * np.array([0.55, 0.7, 0.95]) + t[j] * np.array([0.95, 0.75, 0.5])
write_vol("albedo.vol", albedo)
