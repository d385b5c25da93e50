#!/usr/bin/python3
"""Times LPIPS-VGG16 in PyTorch (CPU, float32) on one 504x378 pair, for comparison with bench/bench_lpips
(docs/benchmarks.md, "LPIPS"). Random weights; torchvision's vgg16().features and the LPIPS head.

Run: /usr/bin/python3 tools/bench_torch_lpips.py [threads]
"""
import sys
import time

import torch
import torchvision

threads = int(sys.argv[1]) if len(sys.argv) > 1 else 2
torch.set_num_threads(threads)
torch.manual_seed(0)
features = torchvision.models.vgg16().features.eval()
taps_end = [4, 9, 16, 23, 30]
lins = [torch.rand(1, c, 1, 1) * 0.1 for c in (64, 128, 256, 512, 512)]
shift = torch.tensor([-.030, -.088, -.188]).view(1, 3, 1, 1)
scale = torch.tensor([.458, .448, .450]).view(1, 3, 1, 1)


def taps(x):
    out, start = [], 0
    x = (x - shift) / scale
    for end in taps_end:
        for m in list(features)[start:end]:
            x = m(x)
        out.append(x)
        start = end
    return out


def lpips(a, b):
    total = 0.0
    for fa, fb, w in zip(taps(a), taps(b), lins):
        na = fa / (fa.pow(2).sum(1, keepdim=True).sqrt() + 1e-10)
        nb = fb / (fb.pow(2).sum(1, keepdim=True).sqrt() + 1e-10)
        total += float(torch.nn.functional.conv2d((na - nb) ** 2, w).mean())
    return total


a, b = torch.rand(1, 3, 378, 504), torch.rand(1, 3, 378, 504)
with torch.no_grad():
    lpips(a, b)  # warm-up
    for _ in range(3):
        t0, c0 = time.perf_counter(), time.process_time()
        lpips(a, b)
        print(f"torch {torch.__version__}, {threads} thread(s): wall {time.perf_counter() - t0:.2f} s, "
              f"process CPU {time.process_time() - c0:.2f} s")
