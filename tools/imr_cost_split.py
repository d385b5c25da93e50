#!/usr/bin/python3
"""What the released IMR's cost is made of, for two trained models: position term against covariance term,
and which depth stratum carries them.

IMR (docs/imr.md) subsamples each model by depth strata along a reference camera's axis (the release: the
first test camera, global image 0; depth |x · R_w2c[:,2]|), builds the cost
    C_ij = |m_i - m_j|^2 + 1/4 tr((S_i - S_j) S_j^-1 (S_i - S_j))     (shape term clamped to [0, max position term])
and solves entropic OT at epsilon = 0.1 times the mean of C (`scale`). At that epsilon the plan is close to the
product of the weights, so the transport cost follows `scale`: how far apart and how different in size the
subsampled components are, before any question of the two models agreeing. This prints, per pair, `scale`
split into its position and shape parts, the far third's share of each, and per stratum the Gaussians' axis
ratios (s_max / s_min) and sizes, with a NumPy version of the release's subsampling and covariance floor.
It does not solve the transport (`d2gs imr` does); it says what the cost it solves is made of.

Usage: tools/imr_cost_split.py [--samples N] RUN/cameras.json MODEL_A.ply MODEL_B.ply [MODEL_C.ply ...]
(every pair of the models, A-B, A-C, B-C, ...; cameras.json of any run of the scene: it holds image 0).
Memory: a few N x N float64 arrays (N = 2 000 by default: ~0.1 GB; the release's 10 000 needs ~3 GB).
"""
import json
import sys

import numpy as np

from plyio import read_ply


def load(path):
    g = read_ply(path)
    x = np.stack([g["x"], g["y"], g["z"]], 1).astype(np.float64)
    alpha = 1.0 / (1.0 + np.exp(-g["opacity"].astype(np.float64)))
    s = np.exp(np.stack([g["scale_0"], g["scale_1"], g["scale_2"]], 1).astype(np.float64))
    q = np.stack([g["rot_0"], g["rot_1"], g["rot_2"], g["rot_3"]], 1).astype(np.float64)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, a, b, c = q.T
    r = np.stack([1 - 2 * (b * b + c * c), 2 * (a * b - w * c), 2 * (a * c + w * b),
                  2 * (a * b + w * c), 1 - 2 * (a * a + c * c), 2 * (b * c - w * a),
                  2 * (a * c - w * b), 2 * (b * c + w * a), 1 - 2 * (a * a + b * b)], 1).reshape(-1, 3, 3)
    cov = np.einsum("nij,nj,nkj->nik", r, s**2, r)
    return x, alpha, s, cov


def reference_axis(cameras_path):
    """Third column of the world-to-camera rotation of global image 0 (the release's depth axis)."""
    with open(cameras_path) as f:
        cameras = json.load(f)
    found = [c for c in cameras if c.get("global_index") == 0]
    if len(found) != 1:
        sys.exit(f"{cameras_path}: no camera with global_index 0 (the release's reference camera)")
    c2w = np.array(found[0]["rotation"], dtype=np.float64)
    return c2w.T[:, 2]


def strata_subsample(x, axis, n):
    """The release's depth-strata subsample: near third stride b+2, middle b, far max(1, b-2)."""
    depth = np.abs(x @ axis) + 1e-6
    order = np.argsort(depth, kind="stable")
    count = len(x)
    m = min(n, count)
    b = count // m
    cut1, cut2 = count // 3, 2 * count // 3  # the thirds of d2gs imr and docs/imr.md: [0, N//3), [N//3, 2N//3), [2N//3, N)
    return np.concatenate([order[:cut1][:: b + 2], order[cut1:cut2][::b], order[cut2:][:: max(1, b - 2)]])


def floor_covariances(cov):
    cov = 0.5 * (cov + cov.transpose(0, 2, 1))
    floor = (1e-3 * np.sqrt(np.diagonal(cov, axis1=1, axis2=2).max())) ** 2
    values, vectors = np.linalg.eigh(cov)
    return np.einsum("nij,nj,nkj->nik", vectors, np.maximum(values, floor), vectors)


def strata(x, axis):
    depth = np.abs(x @ axis)
    return np.argsort(np.argsort(depth, kind="stable"), kind="stable") * 3 // len(depth)


def pair(a, b, axis, n):
    (xa, _, _, ca), (xb, _, _, cb) = a, b
    ia, ib = strata_subsample(xa, axis, n), strata_subsample(xb, axis, n)
    xa, ca, xb, cb = xa[ia], floor_covariances(ca[ia]), xb[ib], floor_covariances(cb[ib])
    position = ((xa[:, None, :] - xb[None, :, :]) ** 2).sum(-1)
    inverse = np.linalg.inv(cb)
    # tr((Sa - Sb) Sb^-1 (Sa - Sb)) = tr(Sa Sb^-1 Sa) - 2 tr(Sa) + tr(Sb)
    quad = np.einsum("ikl,jlm,imk->ij", ca, inverse, ca)
    shape = 0.25 * (quad - 2 * np.trace(ca, axis1=1, axis2=2)[:, None] + np.trace(cb, axis1=1, axis2=2)[None, :])
    shape = np.clip(shape, 0.0, position.max())
    far = strata(xa, axis) == 2
    return {"scale": (position + shape).mean(), "position": position.mean(), "shape": shape.mean(),
            "far_position": position[far].sum() / position.sum(), "far_shape": shape[far].sum() / shape.sum()}


def shapes(model, axis, n):
    x, alpha, s, _ = model
    idx = strata_subsample(x, axis, n)
    x, alpha, s = x[idx], alpha[idx], s[idx]
    k = strata(x, axis)
    rows = []
    for stratum in range(3):
        m = k == stratum
        ratio = s[m].max(1) / s[m].min(1)
        rows.append((np.median(s[m].max(1)), np.quantile(s[m].max(1), 0.9), np.median(ratio), np.quantile(ratio, 0.9),
                     np.median(alpha[m])))
    return rows


def main():
    args = sys.argv[1:]
    n = 2000
    if len(args) >= 2 and args[0] == "--samples":
        n = int(args[1])
        args = args[2:]
    if len(args) < 3 or any(a.startswith("--") for a in args):
        sys.exit(__doc__)
    axis = reference_axis(args[0])
    paths = args[1:]
    models = [load(p) for p in paths]
    print("per model and depth stratum (near, middle, far): largest axis median / 90th pct, axis ratio median / 90th pct, opacity median")
    for path, model in zip(paths, models):
        name = path.split("/point_cloud/")[0][-60:]
        cells = "  ".join(f"{a:.3f}/{b:.2f} {c:.0f}/{d:.0f} {e:.2f}" for a, b, c, d, e in shapes(model, axis, n))
        print(f"  {name}: {cells}")
    print("per pair: scale = mean cost = position + shape; the far third's share of each")
    for i in range(len(models)):
        for j in range(i + 1, len(models)):
            r = pair(models[i], models[j], axis, n)
            print(f"  {i}-{j}: scale {r['scale']:.0f} = position {r['position']:.0f} + shape {r['shape']:.0f}; "
                  f"far third: {r['far_position']:.2f} of position, {r['far_shape']:.2f} of shape")


if __name__ == "__main__":
    main()
