#!/usr/bin/env python3
"""PyTorch peer of the Burn combiner network, for the speed comparison (issue 5 / issue 6).

The same computation as `model` (paper preset): ten 5x5 "same" convolutions 27 -> 9x50 (ReLU)
-> 4*19^2 = 1444, weights ReLU(out) + 1e-4 masked to the image and normalised, the combination
of paper Eq. 6 gathered with F.unfold on an explicitly zero-padded input, the loss of Eq. 8,
Adam (lr 1e-4, eps 1e-8). Prints one JSON object with the median seconds of each measurement.

    python3 bench/peer.py --batch 8 --patch 64 --infer-size 256 --steps 3
"""

import argparse
import json
import statistics
import time

import torch
import torch.nn as nn
import torch.nn.functional as F


class Network(nn.Module):
    """The kernel-predicting network: 27 -> hidden x filters (ReLU) -> 4 * window^2."""

    def __init__(self, hidden=9, filters=50, kernel=5, window=19):
        super().__init__()
        layers, cin = [], 27
        for _ in range(hidden):
            layers += [nn.Conv2d(cin, filters, kernel, padding=kernel // 2), nn.ReLU()]
            cin = filters
        layers.append(nn.Conv2d(cin, 4 * window * window, kernel, padding=kernel // 2))
        self.net = nn.Sequential(*layers)
        self.window = window
        for m in self.modules():
            if isinstance(m, nn.Conv2d):
                nn.init.xavier_uniform_(m.weight)
                nn.init.zeros_(m.bias)

    def forward(self, x):
        return F.relu(self.net(x)) + 1e-4


def inside_mask(h, w, window, device):
    """1 where a window entry lies inside the image: [1, 1, 1, window^2, h*w]."""
    ones = torch.ones(1, 1, h, w, device=device)
    r = window // 2
    return F.unfold(F.pad(ones, (r, r, r, r)), window).reshape(1, 1, 1, window * window, h * w)


def combine(levels, weights, window):
    """Paper Eq. 6: levels [B, 15, H, W] (y, z1..z4 RGB), weights [B, 4*window^2, H, W]."""
    b, _, h, w = levels.shape
    r, area, hw = window // 2, window * window, h * w
    y, z = levels[:, :3], levels[:, 3:]
    d = y.repeat(1, 4, 1, 1) - z
    gathered = F.unfold(F.pad(d, (r, r, r, r)), window).reshape(b, 4, 3, area, hw)
    wts = weights.reshape(b, 4, 1, area, hw) * inside_mask(h, w, window, levels.device)
    sums = wts.sum(3, keepdim=True)
    num = (gathered * wts).sum(3, keepdim=True) + sums * z.reshape(b, 4, 3, 1, hw)
    return (num.sum(1) / sums.sum(1)).reshape(b, 3, h, w)


def loss_fn(pred, ref):
    """Paper Eq. 8."""
    lp, lr = torch.log1p(pred.clamp_min(0)), torch.log1p(ref)
    return ((lp - lr).abs() / (lr.mean(1, keepdim=True) + 0.01)).mean()


def timed(fn, repeats):
    fn()  # warm-up (allocator, oneDNN primitive cache)
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), times


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--batch", type=int, default=8)
    p.add_argument("--patch", type=int, default=64)
    p.add_argument("--infer-size", type=int, default=256)
    p.add_argument("--steps", type=int, default=3)
    p.add_argument("--threads", type=int, default=0, help="torch threads (0: torch default)")
    a = p.parse_args()
    if a.threads > 0:
        torch.set_num_threads(a.threads)
    torch.manual_seed(0)
    net = Network()
    opt = torch.optim.Adam(net.parameters(), lr=1e-4, eps=1e-8)
    s, bs = a.patch, a.batch
    feats = torch.rand(bs, 27, s, s)
    levels = torch.rand(bs, 15, s, s)
    ref = torch.rand(bs, 3, s, s)

    def step():
        opt.zero_grad(set_to_none=True)
        loss = loss_fn(combine(levels, net(feats), net.window), ref)
        loss.backward()
        opt.step()

    train_median, train_times = timed(step, a.steps)

    n = a.infer_size
    f_img, l_img = torch.rand(1, 27, n, n), torch.rand(1, 15, n, n)

    def infer():
        with torch.no_grad():
            combine(l_img, net(f_img), net.window)

    infer_median, infer_times = timed(infer, max(1, a.steps))
    print(json.dumps({
        "framework": f"pytorch {torch.__version__}",
        "threads": torch.get_num_threads(),
        "params": sum(p.numel() for p in net.parameters()),
        "train_step_s": train_median,
        "train_step_all_s": train_times,
        "infer_s": infer_median,
        "infer_all_s": infer_times,
        "batch": bs, "patch": s, "infer_size": n,
    }))


if __name__ == "__main__":
    main()
