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

Usage: tools/model_moments.py RUN/point_cloud/iteration_10000/point_cloud.ply ...
These are descriptions of the models, not the IMR itself (`d2gs imr` computes that).
"""
import sys

import numpy as np

from plyio import read_ply


def moments(path):
    g = read_ply(path)
    x = np.stack([g["x"], g["y"], g["z"]], 1).astype(np.float64)
    alpha = 1.0 / (1.0 + np.exp(-g["opacity"].astype(np.float64)))
    w = alpha / alpha.sum()
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


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    print(f"{'model':60s} {'N':>7s} {'mean_alpha':>10s} {'frac<0.05':>9s} {'r2':>8s} {'far_w':>6s} {'smax':>6s} {'max_r':>7s}")
    for path in sys.argv[1:]:
        m = moments(path)
        name = path.split("/point_cloud/")[0][-60:]
        print(f"{name:60s} {m['N']:7d} {m['mean_alpha']:10.3f} {m['frac<0.05']:9.2f} {m['r2']:8.1f} "
              f"{m['far_w']:6.3f} {m['smax']:6.3f} {m['max_r']:7.1f}")


if __name__ == "__main__":
    main()
