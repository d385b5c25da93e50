#!/usr/bin/python3
"""Times POT's NumPy log-domain Sinkhorn on one IMR pair (docs/benchmarks.md, "IMR / Sinkhorn").

Writes two random Gaussian models of N components (seeded, same generator as tools/make_imr_fixtures.py)
as .npy files into OUT_DIR, builds the release cost (Taylor-Bures, shape clamped, divided by its mean) with
NumPy, and times ot.sinkhorn2(a, b, C, 0.1, method='sinkhorn_log'). Then run d2gs on the same pair:
    D2GS_IMR_BENCH_DIR=OUT_DIR build/bench/bench_imr --benchmark_filter=BM_ImrPair/N/
Usage: /usr/bin/python3 tools/bench_pot_sinkhorn.py [N=10000] [OUT_DIR=/tmp/d2gs_imr_bench] [STOP_THR=1e-5]
Needs numpy and ot (apt-get install python3-pot). Memory: about 5 * N^2 * 8 bytes (4 GB for N = 10 000).
"""
import os
import sys
import time

import numpy as np
import ot

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from make_imr_fixtures import mixture, random_model  # noqa: E402


def release_cost(ma, ca, mb, cb, chunk=500):
    """Taylor-Bures cost, rows in chunks (the same formula as the fixtures, vectorised over j)."""
    n, m = len(ma), len(mb)
    pos = ((ma[:, None, :] - mb[None, :, :]) ** 2).sum(-1)
    inv_b = np.linalg.inv(cb)
    shape = np.empty((n, m))
    for i0 in range(0, n, chunk):
        d = ca[i0:i0 + chunk, None, :, :] - cb[None, :, :, :]  # (chunk, m, 3, 3)
        shape[i0:i0 + chunk] = 0.25 * np.einsum("ijab,jbc,ijca->ij", d, inv_b, d, optimize=True)
    np.clip(shape, 0.0, pos.max(), out=shape)
    pos += shape
    del shape
    scale = pos.mean()
    pos /= scale
    return pos, scale


def main():
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 10000
    out_dir = sys.argv[2] if len(sys.argv) > 2 else "/tmp/d2gs_imr_bench"
    stop = float(sys.argv[3]) if len(sys.argv) > 3 else 1e-5
    os.makedirs(out_dir, exist_ok=True)
    rng = np.random.default_rng(12345)
    models = {"a": random_model(rng, n), "b": random_model(rng, n)}
    for prefix, model in models.items():
        for key, arr in model.items():
            np.save(os.path.join(out_dir, f"{prefix}_{key}.npy"), arr)
    (ma, ca, wa), (mb, cb, wb) = mixture(models["a"]), mixture(models["b"])
    t0 = time.perf_counter()
    c, scale = release_cost(ma, ca, mb, cb)
    t1 = time.perf_counter()
    value, log = ot.sinkhorn2(wa, wb, c, 0.1, method="sinkhorn_log", numItermax=10000, stopThr=stop, log=True)
    t2 = time.perf_counter()
    print(f"POT {ot.__version__} sinkhorn_log, N = {n}, eps = 0.1 on the normalised cost, stopThr = {stop}")
    print(f"  cost matrix (NumPy): {t1 - t0:.2f} s; Sinkhorn: {t2 - t1:.2f} s; iterations {log['niter'] + 1}; "
          f"final marginal error (L2) {log['err'][-1]:.2e}")
    print(f"  S = scale * <P, C~> = {scale * value:.10g} (scale {scale:.10g}, <P, C~> {value:.10g})")


if __name__ == "__main__":
    main()
