#!/usr/bin/python3
"""Where a trained model's Gaussians lie against the depth range of its own initial cloud (the training views'
stereo), and how much of the released IMR subsample's position spread the farthest of them carry: whether a
few far-out components, or the whole spread of the scene, make a model's IMR `scale` (docs/imr.md).

Usage: tools/imr_far_components.py RUN [MODEL.ply]   (RUN: a d2gs train folder with config.json, cameras.json
and init/dense/fused.ply; MODEL: default RUN/point_cloud/iteration_10000/point_cloud.ply)
The depth of a Gaussian is its smallest depth over the training cameras; "init q99" is the 99th percentile of
the init cloud's largest depth over them. The position spread is the mean squared distance of the 10 000-sample
subsample (the release's depth strata) to its centroid, half the mean pairwise position term of the cost.
"""
import json, sys
import numpy as np
sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parent))
from plyio import read_ply
from imr_cost_split import load, reference_axis, strata_subsample, floor_covariances

run = sys.argv[1]
cfg = json.load(open(f"{run}/config.json"))
cams = json.load(open(f"{run}/cameras.json"))
train = [c for c in cams if c["global_index"] in cfg["split"]["train"]]
ply = sys.argv[2] if len(sys.argv) > 2 else f"{run}/point_cloud/iteration_10000/point_cloud.ply"
x, alpha, s, cov = load(ply)
init = read_ply(f"{run}/init/dense/fused.ply")
xi = np.stack([init["x"], init["y"], init["z"]], 1).astype(np.float64)

def depths(p):
    return np.stack([(p - np.array(c["position"])) @ np.array(c["rotation"])[:, 2] for c in train], 1)

di = depths(xi)
dmax_init = np.quantile(di.max(1), 0.99)
dg = depths(x)
dmin = dg.min(1)  # nearest training view's depth
print(f"{ply}: {len(x)} Gaussians; init cloud depth q50 {np.median(di):.1f} q99 {dmax_init:.1f} max {di.max():.1f}")
for f in [1, 1.5, 2, 4, 10]:
    m = dmin > f * dmax_init
    print(f"  beyond {f:4} x init q99 depth (all train views): {m.sum():6d} ({m.mean()*100:.2f} %), opacity-sum share {alpha[m].sum()/alpha.sum()*100:.2f} %")
m = dmin < 0
print(f"  behind a training camera (min depth < 0): {m.sum()}")
print(f"  depth q50/q90/q99/max {np.quantile(dmin,[.5,.9,.99,1])}; max axis q50/q90/q99/max {np.quantile(s.max(1),[.5,.9,.99,1])}")
# contribution to the unweighted mean cost (position part) of the release's subsample of this model against itself
axis = reference_axis(f"{run}/cameras.json")
idx = strata_subsample(x, axis, 10000)
xs = x[idx]
mu = xs.mean(0)
# mean over pairs |xi-xj|^2 = 2 * mean |xi - mu|^2 ; per-component share
d2 = ((xs - mu) ** 2).sum(1)
order = np.argsort(-d2)
tot = d2.sum()
for k in [10, 100, 1000]:
    print(f"  subsample of {len(idx)}: the {k} farthest from its centroid hold {d2[order[:k]].sum()/tot*100:.1f} % of the position spread")
far = dmin[idx] > 2 * dmax_init
print(f"  subsample components beyond 2x init q99: {far.sum()}, their share of the position spread {d2[far].sum()/tot*100:.1f} %")
