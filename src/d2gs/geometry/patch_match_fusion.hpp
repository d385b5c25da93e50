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
  double max_normal_deg = 10.0;
  int max_traversal_depth = 100;
  // COLMAP asks for 5 pixels, meant for many views; with 3 views a point has about one pixel per view
  // that sees it, so 2 = one other view agrees (the evidence of a two-view track).
  int min_pixels = 2;
  // Only points whose first pixel lies on this grid of its view (every stride-th pixel of each axis) are
  // written; the others still take their pixels. 1 = every point (COLMAP). 3 keeps fern's cloud (3 views
  // at 1008x756) at about the size of the SGBM cloud and of the published one (15–18k points), so that
  // an init comparison is not one of point counts.
  int pixel_stride = 3;
};

// Throws d2gs::Error naming the option when one is out of range.
void validate(const PatchMatchFusionOptions& options);

// Points with normals (PointCloud::normals) and colours from `images` (RGB, the maps' size). Deterministic.
PointCloud fuse_patch_match(const std::vector<const Camera*>& cameras, const std::vector<const Image*>& images,
                            const std::vector<PatchMatchMap>& maps, const PatchMatchFusionOptions& options);

}  // namespace d2gs
