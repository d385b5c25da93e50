#!/usr/bin/python3
"""Compare an initial cloud of fern's 3 training views with the published pipeline's (docs/benchmarks.md,
"PatchMatch stereo"): point counts, spacing (mean distance to the 3 nearest neighbours), distances between
the clouds, the far background each covers, and how many points pass COLMAP's default depth-map filter
(triangulation angle >= 3 degrees to both sources of a reference view) from each training view.

Run from the repository root:
  /usr/bin/python3 tools/compare_init_clouds.py OURS.ply [PUBLISHED.ply]
Cameras: the centres of ../shared/data/nerf_llff_data/fern/poses_bounds.npy, training views 1, 10, 19
(every 8th image held out, 3 views spread evenly over the rest, as the sparse-view papers choose them).
"""
import pathlib
import sys

import numpy as np
from scipy.spatial import cKDTree

from plyio import read_xyz

ROOT = pathlib.Path(__file__).resolve().parent.parent
FERN = ROOT.parent / "shared" / "data" / "nerf_llff_data" / "fern"
PUBLISHED = ROOT.parent / "shared" / "data" / "published_init" / "fern" / "3_views_fused.ply"
TRAIN_VIEWS = [1, 10, 19]
FAR_DEPTH = 40.0  # view 10's depth beyond which fern's scene is the hall behind the plant


def camera(poses, k):
    m = poses[k, :15].reshape(3, 5)
    c2w = np.stack([m[:, 1], m[:, 0], -m[:, 2]], 1)  # LLFF's (down, right, back) to (right, down, forward)
    return c2w.T, m[:, 3]


def angle_deg(points, c1, c2):
    r1, r2 = points - c1, points - c2
    c = (r1 * r2).sum(1) / np.linalg.norm(r1, axis=1) / np.linalg.norm(r2, axis=1)
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))


def describe(name, points, poses):
    centres = [camera(poses, k)[1] for k in TRAIN_VIEWS]
    pairs = [(0, 1), (0, 2), (1, 2)]
    angles = np.stack([angle_deg(points, centres[a], centres[b]) for a, b in pairs], 1)
    r10, c10 = camera(poses, TRAIN_VIEWS[1])
    depth = (points - c10) @ r10[2]
    spacing = cKDTree(points).query(points, k=4)[0][:, 1:].mean(1)
    print(f"{name}: {len(points)} points, spacing (median of mean 3-NN distance) {np.median(spacing):.4f}, "
          f"depth in view 10 p10/p50/p90 {np.percentile(depth, 10):.1f}/{np.percentile(depth, 50):.1f}/"
          f"{np.percentile(depth, 90):.1f}, beyond {FAR_DEPTH:g}: {(depth > FAR_DEPTH).sum()}")
    for ref in range(3):
        own = [i for i, (a, b) in enumerate(pairs) if ref in (a, b)]
        passing = (angles[:, own] >= 3.0).all(1).mean()
        print(f"  passes the 3-degree, 2-source filter as view {TRAIN_VIEWS[ref]}'s depth: {passing:.3f}")
    print(f"  no pair at >= 3 degrees: {(angles.max(1) < 3.0).mean():.3f}")


def main():
    if len(sys.argv) not in (2, 3):
        sys.exit(__doc__)
    ours = read_xyz(sys.argv[1])
    theirs = read_xyz(sys.argv[2] if len(sys.argv) == 3 else PUBLISHED)
    poses = np.load(FERN / "poses_bounds.npy")
    describe("ours", ours, poses)
    describe("published", theirs, poses)
    lo, hi = np.percentile(theirs, 2, axis=0), np.percentile(theirs, 98, axis=0)
    extent = np.linalg.norm(hi - lo)
    acc = cKDTree(theirs).query(ours)[0]
    comp = cKDTree(ours).query(theirs)[0]
    print(f"accuracy (median distance ours -> published) {np.median(acc) / extent:.4f} of the extent {extent:.1f}; "
          f"completeness (published -> ours) {np.median(comp) / extent:.4f}; "
          f"published points farther than 1.5 from ours: {(comp > 1.5).sum()}")


if __name__ == "__main__":
    main()
