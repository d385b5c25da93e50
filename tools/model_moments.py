#!/usr/bin/python3
"""Opacity-weighted moments of trained 3DGS models: what the IMR's Wasserstein cost weighs.

IMR (docs/imr.md) compares models as Gaussian mixtures with weights alpha_i / sum(alpha), and its cost is
the squared distance of the means plus a covariance term. This prints, per model PLY (the 3DGS layout that
`d2gs train` writes: x y z, opacity logit, log scales), the quantities that move that cost:

  N            number of Gaussians
  mean_alpha   mean opacity; frac<0.05: share of Gaussians below opacity 0.05
  r2           alpha-weighted mean squared distance from the alpha-weighted centroid (scene units^2)
  far_w        alpha-weight beyond 3x the (unweighted) median distance from that centroid
  smax         alpha-weighted mean of each Gaussian's largest axis (exp of its largest log scale)
  max_r        largest distance from the centroid

Usage: tools/model_moments.py [--depth-from CAMERAS.json IMAGE_NAME] RUN/point_cloud/iteration_10000/point_cloud.ply ...

With --depth-from, each model also gets alpha-weighted quantiles of its Gaussians' depth along that camera's
viewing axis (a camera of a run's cameras.json, named by its img_name, e.g. image010): where the model's
opacity sits, near to far (d10 .. d99), and the alpha-weight beyond depth FAR (default 40: fern's far wall
lies at 75-80 from its middle training view; set with --far).
These are descriptions of the models, not the IMR itself (`d2gs imr` computes that).
"""
import json
import sys

import numpy as np

from plyio import read_ply


def load(path):
    """A model's PLY with its positions (N×3), opacities and IMR weights alpha / sum(alpha)."""
    g = read_ply(path)
    x = np.stack([g["x"], g["y"], g["z"]], 1).astype(np.float64)
    alpha = 1.0 / (1.0 + np.exp(-g["opacity"].astype(np.float64)))
    return g, x, alpha, alpha / alpha.sum()


def moments(g, x, alpha, w):
    scale = np.exp(np.stack([g["scale_0"], g["scale_1"], g["scale_2"]], 1).astype(np.float64)).max(1)
    centre = (w[:, None] * x).sum(0)
    r = np.sqrt(((x - centre) ** 2).sum(1))
    return {
        "N": len(alpha),
        "mean_alpha": alpha.mean(),
        "frac<0.05": (alpha < 0.05).mean(),
        "r2": (w * r**2).sum(),
        "far_w": w[r > 3 * np.median(r)].sum(),
        "smax": (w * scale).sum(),
        "max_r": r.max(),
    }


QUANTILES = (0.1, 0.5, 0.9, 0.95, 0.99)


def camera_axis(cameras_path, image_name):
    """Centre and viewing axis (third column of the camera-to-world rotation) of one camera of a cameras.json."""
    with open(cameras_path) as f:
        cameras = json.load(f)
    found = [c for c in cameras if c.get("img_name") == image_name]
    if len(found) != 1:
        names = ", ".join(c.get("img_name", "?") for c in cameras)
        sys.exit(f"{cameras_path}: no camera named '{image_name}' (cameras: {names})")
    return np.array(found[0]["position"], dtype=np.float64), np.array(found[0]["rotation"], dtype=np.float64)[:, 2]


def depth_profile(x, w, centre, axis, far):
    depth = (x - centre) @ axis
    order = np.argsort(depth)
    cumulative = np.cumsum(w[order])
    q = [depth[order][min(np.searchsorted(cumulative, f), len(order) - 1)] for f in QUANTILES]
    return q, w[depth > far].sum()


def main():
    args = sys.argv[1:]
    depth_from = None
    far = 40.0
    while args and args[0].startswith("--"):
        if args[0] == "--depth-from" and len(args) >= 3:
            depth_from = camera_axis(args[1], args[2])
            args = args[3:]
        elif args[0] == "--far" and len(args) >= 2:
            far = float(args[1])
            args = args[2:]
        else:
            sys.exit(__doc__)
    if not args:
        sys.exit(__doc__)
    header = f"{'model':60s} {'N':>7s} {'mean_alpha':>10s} {'frac<0.05':>9s} {'r2':>8s} {'far_w':>6s} {'smax':>6s} {'max_r':>7s}"
    if depth_from is not None:
        header += "".join(f" {'d' + str(round(100 * f)):>6s}" for f in QUANTILES) + f" {'w(d>' + f'{far:g}' + ')':>9s}"
    print(header)
    for path in args:
        g, x, alpha, w = load(path)
        m = moments(g, x, alpha, w)
        name = path.split("/point_cloud/")[0][-60:]
        row = (f"{name:60s} {m['N']:7d} {m['mean_alpha']:10.3f} {m['frac<0.05']:9.2f} {m['r2']:8.1f} "
               f"{m['far_w']:6.3f} {m['smax']:6.3f} {m['max_r']:7.1f}")
        if depth_from is not None:
            q, w_far = depth_profile(x, w, *depth_from, far)
            row += "".join(f" {v:6.1f}" for v in q) + f" {w_far:9.3f}"
        print(row)


if __name__ == "__main__":
    main()
