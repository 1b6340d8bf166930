#!/usr/bin/env python3
"""Writes the voxel grid of the `media-phases` validation scene (run from this folder; numpy):

* weight.vol: 8 x 1 x 1, one channel, the blend weight rising linearly from 0 to 1 along x
  (cell centres), so the blended fog turns from its first phase function into its second.

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


n = 8
weight = np.linspace(0.0, 1.0, n).reshape(1, 1, n, 1)
write_vol("weight.vol", weight)
