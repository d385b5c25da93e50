#!/usr/bin/python3
"""Writes the IMR / Sinkhorn test fixtures of tests/eval/fixtures/ (see docs/imr.md).

Independent reference for d2gs's IMR: random Gaussian models (seeded) are turned into mixtures, their IMR
cost matrix is computed here with NumPy directly from the formulas of method.md §7 (release clamping and
mean normalisation), and the entropic transport cost is computed by POT (Debian package python3-pot):
ot.sinkhorn2(a, b, M, reg=eps, method='sinkhorn_log'), which returns <P, M> without the entropy term and
whose reg is the ε of d2gs (POT's entropy Σ P log P differs from Σ P (log P − 1) by the constant Σ P = 1,
so the plans agree). Only the model parameters are stored (float32 .npy); the C++ test recomputes
the mixture, the cost and the transport and compares with the numbers in imr_fixtures.json.

Usage: /usr/bin/python3 tools/make_imr_fixtures.py [OUT_DIR]   (default tests/eval/fixtures)
Needs numpy and ot (apt-get install python3-pot); the C++ tests need neither.
"""
import json
import os
import sys
import time

import numpy as np
import ot


def random_model(rng, n, center=(0.0, 0.0, 4.0), spread=(2.0, 1.5, 2.0), thin_fraction=0.1):
    """Raw 3DGS parameters (before activation): means, log_scales, quats (w x y z), opacity logits."""
    means = rng.normal(center, spread, size=(n, 3))
    log_scales = rng.normal(np.log(0.03), 0.6, size=(n, 3))
    thin = rng.random(n) < thin_fraction  # a few flat Gaussians so the eigenvalue clamp is exercised
    log_scales[thin, 2] = -14.0
    quats = rng.normal(size=(n, 4))
    quats[rng.random(n) < 0.05] *= 7.0  # unnormalised on purpose: normalised at use
    opacity = rng.normal(0.0, 2.0, size=n)
    return {
        "means": means.astype(np.float32),
        "log_scales": log_scales.astype(np.float32),
        "quats": quats.astype(np.float32),
        "opacity_logits": opacity.astype(np.float32),
    }


def quat_to_rot(q):
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    r = np.empty((len(q), 3, 3))
    r[:, 0, 0] = 1 - 2 * (y * y + z * z)
    r[:, 0, 1] = 2 * (x * y - w * z)
    r[:, 0, 2] = 2 * (x * z + w * y)
    r[:, 1, 0] = 2 * (x * y + w * z)
    r[:, 1, 1] = 1 - 2 * (x * x + z * z)
    r[:, 1, 2] = 2 * (y * z - w * x)
    r[:, 2, 0] = 2 * (x * z - w * y)
    r[:, 2, 1] = 2 * (y * z + w * x)
    r[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return r


def mixture(model, sanitize=True):
    means = model["means"].astype(np.float64)
    scales = np.exp(model["log_scales"].astype(np.float64))
    rot = quat_to_rot(model["quats"].astype(np.float64))
    rs = rot * scales[:, None, :]
    cov = rs @ np.transpose(rs, (0, 2, 1))
    alpha = 1.0 / (1.0 + np.exp(-model["opacity_logits"].astype(np.float64)))
    weights = alpha / alpha.sum()
    if sanitize:
        cov = 0.5 * (cov + np.transpose(cov, (0, 2, 1)))
        floor = (1e-3 * np.sqrt(np.max(np.diagonal(cov, axis1=1, axis2=2)))) ** 2
        vals, vecs = np.linalg.eigh(cov)
        clamped = vals.min(axis=1) < floor
        vals = np.maximum(vals, floor)
        rebuilt = vecs @ (vals[:, :, None] * np.transpose(vecs, (0, 2, 1)))
        cov = np.where(clamped[:, None, None], 0.5 * (rebuilt + np.transpose(rebuilt, (0, 2, 1))), cov)
    return means, cov, weights


def sqrtm_sym(c):
    vals, vecs = np.linalg.eigh(c)
    return vecs @ (np.sqrt(np.maximum(vals, 0.0))[..., :, None] * np.swapaxes(vecs, -1, -2))


def cost_matrix(ma, ca, mb, cb, shape="taylor", clamp=True, normalize=True):
    """C[i, j] between source component i (A) and target j (B), computed directly from the formulas."""
    pos = ((ma[:, None, :] - mb[None, :, :]) ** 2).sum(-1)
    if shape == "taylor":
        inv_b = np.linalg.inv(cb)
        shp = np.empty_like(pos)
        for i in range(len(ma)):  # row by row: (Σ_i − Σ_j) Σ_j⁻¹ (Σ_i − Σ_j), trace
            d = ca[i][None, :, :] - cb
            shp[i] = 0.25 * np.einsum("jab,jbc,jca->j", d, inv_b, d)
    else:
        sb = sqrtm_sym(cb)
        shp = np.empty_like(pos)
        tr_a = np.trace(ca, axis1=1, axis2=2)
        tr_b = np.trace(cb, axis1=1, axis2=2)
        for i in range(len(ma)):
            m = sb @ ca[i][None, :, :] @ sb
            m = 0.5 * (m + np.swapaxes(m, -1, -2))
            ev = np.linalg.eigvalsh(m)
            shp[i] = tr_a[i] + tr_b - 2.0 * np.sqrt(np.maximum(ev, 0.0)).sum(-1)
    if clamp:
        shp = np.clip(shp, 0.0, pos.max())
    c = pos + shp
    scale = c.mean() if normalize else 1.0
    return c / scale, scale, pos.max()


def depth_strata(model, r_w2c, samples):
    depth = np.abs(model["means"].astype(np.float64) @ r_w2c[:, 2]) + 1e-6
    order = np.argsort(depth, kind="stable")
    n_total = len(depth)
    n = min(samples, n_total)
    b = n_total // n
    c1, c2 = n_total // 3, 2 * n_total // 3
    return np.concatenate([order[0:c1:b + 2], order[c1:c2:b], order[c2:n_total:max(1, b - 2)]])


def save_model(out_dir, name, model):
    files = {}
    for key, arr in model.items():
        fname = f"{name}_{key}.npy"
        np.save(os.path.join(out_dir, fname), arr)
        files[key] = fname
    return files


def main():
    out_dir = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "..", "tests", "eval",
                                                                   "fixtures")
    os.makedirs(out_dir, exist_ok=True)
    rng = np.random.default_rng(20260401)
    cases = []
    models = {}

    def model(name, n):
        if name not in models:
            models[name] = (random_model(rng, n), None)
            models[name] = (models[name][0], save_model(out_dir, name, models[name][0]))
        return models[name]

    def add_case(name, a_name, n_a, b_name, n_b, eps, shape="taylor", clamp=True, normalize=True):
        ma_raw, fa = model(a_name, n_a)
        mb_raw, fb = model(b_name, n_b)
        m_a, c_a, w_a = mixture(ma_raw)
        m_b, c_b, w_b = mixture(mb_raw)
        c, scale, max_pos = cost_matrix(m_a, c_a, m_b, c_b, shape, clamp, normalize)
        start = time.perf_counter()
        transport, log = ot.sinkhorn2(w_a, w_b, c, eps, method="sinkhorn_log", numItermax=20000, stopThr=1e-11,
                                      log=True)
        seconds = time.perf_counter() - start
        picks = [(0, 0), (len(m_a) - 1, len(m_b) - 1)] + [(int(rng.integers(len(m_a))), int(rng.integers(len(m_b))))
                                                         for _ in range(6)]
        cases.append({
            "name": name, "a": fa, "b": fb, "epsilon": eps, "shape": shape, "clamp": clamp, "normalize": normalize,
            "scale": float(scale), "max_position_term": float(max_pos),
            "entries": [[i, j, float(c[i, j])] for i, j in picks],
            "normalized_transport_cost": float(transport), "transport_cost": float(scale * transport),
            "pot_iterations": int(log["niter"]), "pot_final_error": float(log["err"][-1]), "pot_seconds": seconds,
        })
        print(f"{name}: {n_a}x{n_b} eps={eps} {shape} S={scale * transport:.10g} "
              f"(normalised {transport:.10g}, {log['niter']} its, {seconds:.2f} s)")

    add_case("taylor_50", "m50a", 50, "m50b", 50, 0.1)
    add_case("taylor_500", "m500a", 500, "m500b", 500, 0.1)
    add_case("taylor_500_eps0.02", "m500a", 500, "m500b", 500, 0.02)
    add_case("taylor_500_raw", "m500a", 500, "m500b", 500, 0.5, clamp=False, normalize=False)
    add_case("bures_500", "m500a", 500, "m500b", 500, 0.1, shape="exact")
    add_case("taylor_2000", "m2000a", 2000, "m2000b", 2000, 0.1)
    add_case("taylor_50_500", "m50a", 50, "m500b", 500, 0.1)
    add_case("taylor_500_self", "m500a", 500, "m500a", 500, 0.1)

    # Depth strata of the 2000-Gaussian model w.r.t. a rotated reference camera.
    ang = 0.3
    r_w2c = np.array([[np.cos(ang), 0.0, np.sin(ang)], [0.0, 1.0, 0.0], [-np.sin(ang), 0.0, np.cos(ang)]])
    strata = {
        "model": models["m2000a"][1], "R_world_to_cam_row_major": r_w2c.flatten().tolist(),
        "selections": {str(s): depth_strata(models["m2000a"][0], r_w2c, s).tolist() for s in (300, 700, 2000)},
    }
    with open(os.path.join(out_dir, "imr_fixtures.json"), "w") as f:
        json.dump({"generator": "tools/make_imr_fixtures.py", "pot_version": ot.__version__,
                   "numpy_version": np.__version__, "cases": cases, "depth_strata": strata}, f, indent=1)


if __name__ == "__main__":
    main()
