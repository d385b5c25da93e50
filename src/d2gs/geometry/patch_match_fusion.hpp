#pragma once
// Fusion of PatchMatch depth + normal maps into one cloud with normals, in the spirit of COLMAP's
// stereo_fusion: views are visited in order and every pixel with a depth that no earlier point has taken
// starts a new point; its 3D point is projected into the other views, and a pixel there joins the point
// when it agrees with the first pixel (reprojection error, relative depth error, normal angle); joined
// pixels are projected on in turn (a traversal across views). Every pixel joins at most one point. A point
// with at least `min_pixels` pixels is kept: mean position, normal and colour of its pixels.
#include <vector>

#include "d2gs/core/image.hpp"
#include "d2gs/geometry/patch_match.hpp"
#include "d2gs/model/point_cloud.hpp"
#include "d2gs/scene/camera.hpp"

namespace d2gs {

struct PatchMatchFusionOptions {
  double max_reprojection_px = 2.0;   // COLMAP's defaults
  double max_relative_depth = 0.01;
  // COLMAP compares normals within 10°, at 4× our resolution on LLFF (its 4032-px originals; we have
  // 1008 px at most). Our normals, from windows 4× wider in the scene, disagree more (fern's far
  // background: median 39° from the local plane of the points), so a 10° test drops most of the far
  // background the training needs; 180 = no normal test, the depth and reprojection tests remain. Fern,
  // DropGaussian at iteration 2 000: 10° 22.06 dB, 30° 22.54, off 22.68 (docs/benchmarks.md).
  double max_normal_deg = 180.0;
  int max_traversal_depth = 100;
  // COLMAP asks for 5 pixels, meant for many views; with 3 views a point has about one pixel per view
  // that sees it, so 2 = one other view agrees (the evidence of a two-view track).
  int min_pixels = 2;
  // Only points whose first pixel lies on this grid of its view (every stride-th pixel of each axis) are
  // written; the others still take their pixels. 1 = every point (COLMAP). 3: fern's 3 views at
  // 1008x756 give 43k points (15.6k with the 10° normal test; SGBM 14.5k, the published cloud 17.9k);
  // 1 would give 140k (with the normal test) and slow training for no measured gain.
  int pixel_stride = 3;
  // Colour agreement (ours, no COLMAP counterpart): a fused point is dropped when, in some view where it
  // is not hidden (no depth of that view's map lies in front of it: its depth ≤ color_visibility_margin ×
  // the map's depth at its pixel, or the map has none there), its colour differs from the image there by
  // more than this mean absolute RGB difference (images in [0, 1], blurred by a 5×5 Gaussian of σ 1 px so
  // that a pixel's worth of misregistration on an edge is forgiven). It removes what the depth tests
  // cannot: points that several views agree on but that lie in mid-air, over glass or in front of a
  // thin object, coloured by the one view that saw the surface behind them; another view sees through
  // them to a different colour. 0 = off. DropGaussian, 10 000 iterations, 0.10 against off: horns +1.2 dB,
  // room and fern: docs/benchmarks.md, "The colour test at 10 000 iterations".
  double max_color_difference = 0.10;
  double color_visibility_margin = 1.03;
};

struct PatchMatchFusionStats {
  std::size_t fused = 0;          // points before the colour test
  std::size_t color_dropped = 0;  // removed by it
};

// Throws d2gs::Error naming the option when one is out of range.
void validate(const PatchMatchFusionOptions& options);

// Points with normals (PointCloud::normals) and colours from `images` (RGB, the maps' size). Deterministic.
PointCloud fuse_patch_match(const std::vector<const Camera*>& cameras, const std::vector<const Image*>& images,
                            const std::vector<PatchMatchMap>& maps, const PatchMatchFusionOptions& options,
                            PatchMatchFusionStats* stats = nullptr);

// The colour test above on any cloud (colours in cloud.colors), with each view's image and depth map (the
// camera's size; depth 0 = none). Removes the points that fail it, keeping the order; returns how many.
// max_difference ≤ 0: removes nothing. Deterministic whatever the thread count.
std::size_t drop_color_disagreeing_points(PointCloud& cloud, const std::vector<const Camera*>& cameras,
                                          const std::vector<const Image*>& images,
                                          const std::vector<const DepthMap*>& depths, double max_difference,
                                          double visibility_margin);

}  // namespace d2gs
