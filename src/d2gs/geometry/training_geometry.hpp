#pragma once
// Initial geometry from the training views only (method.md §3; issue #6), in the role of the published
// pipeline's COLMAP triangulation + patch-match stereo + fusion:
//   sparse: SIFT in every training view, matching between every pair (ratio test, mutual check,
//           epipolar filter from the known poses), tracks (union-find), triangulation (DLT + refinement,
//           cheirality / reprojection / angle filters), colours from the images;
//   dense:  either PatchMatch multi-view stereo (patch_match.hpp: depth + normal per pixel against all
//           other views, geometric consistency, filter) fused across views (patch_match_fusion.hpp), or
//           rectified SGBM stereo between neighbouring views (disparity range from the sparse points),
//           per-view depth maps filtered by cross-view consistency, fused into one coloured cloud; the
//           depth maps are also the DAFE depth priors.
// Resolution: the training resolution (-r), or the highest the scene folder offers (images/ when present,
// else the largest images_N/), capped on its longest side; PatchMatch uses the highest by default, as the
// published pipeline does (COLMAP on the full-resolution images), SGBM the training resolution.
// Only the given views' images are decoded. The files (write_training_geometry) are
//   DIR/init.json, DIR/sparse/points3D.ply, DIR/dense/fused.ply, DIR/depth/NAME.npy (float32 H×W,
//   camera-space z, 0 = invalid) and DIR/depth/NAME_valid.png (255 = valid),
// with DIR = SCENE/{N}_views by default (training_geometry_dir).
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "d2gs/geometry/fusion.hpp"
#include "d2gs/geometry/matching.hpp"
#include "d2gs/geometry/patch_match.hpp"
#include "d2gs/geometry/patch_match_fusion.hpp"
#include "d2gs/geometry/stereo.hpp"
#include "d2gs/geometry/triangulation.hpp"
#include "d2gs/model/point_cloud.hpp"
#include "d2gs/scene/scene.hpp"

namespace d2gs {

enum class DenseMethod { Sgbm, PatchMatch };
const char* to_string(DenseMethod method);
DenseMethod parse_dense_method(const std::string& name);  // "sgbm" | "patchmatch"; throws otherwise

// Resolution of the images the geometry is computed from.
enum class GeometryResolution {
  Auto,      // Highest for PatchMatch, Training for SGBM
  Training,  // the scene's -r
  Highest,   // the largest image folder, capped by max_image_size
};
const char* to_string(GeometryResolution resolution);
GeometryResolution parse_geometry_resolution(const std::string& name);  // "auto" | "training" | "highest"

struct TrainingGeometryOptions {
  int max_features = 8000;
  double sift_contrast_threshold = 0.04;
  MatchOptions match;                    // match.epipolar_px ≤ 0: 0.4 % of the image diagonal
  TriangulationOptions triangulation;
  int min_sparse_points = 20;            // fewer: the views do not overlap enough (error)
  bool dense = true;
  DenseMethod dense_method = DenseMethod::Sgbm;
  GeometryResolution resolution = GeometryResolution::Auto;
  // Highest: the image folder is divided by 2, 4, ... (up to 1/8 of full resolution) until its longest
  // side is at most this (4032-px phone originals → 1008 px); ≤ 0: no cap.
  int max_image_size = 1600;
  int stereo_neighbors = 2;              // SGBM: each view is paired with its nearest views (camera centres)
  StereoOptions stereo;
  FusionOptions fusion;                  // SGBM's fusion
  PatchMatchOptions patch_match;         // patch_match.seed is replaced by `seed`
  PatchMatchFusionOptions patch_match_fusion;
  std::size_t max_dense_points = 300000; // larger fused clouds are subsampled (seeded)
  std::uint64_t seed = 0;
};

// Throws d2gs::Error naming the option (as `d2gs init` spells it) when a value cannot give a geometry: NaN,
// a ratio outside (0, 1], a count below 1, a negative threshold; the PatchMatch and its fusion's options
// are checked by their own validate. Called by d2gs init and d2gs train before any work.
void validate(const TrainingGeometryOptions& options);

struct StepTiming {
  std::string step;
  double seconds = 0.0;
};

struct TrainingGeometry {
  std::vector<int> views;                 // global indices of the training views
  int geometry_resolution = 1;            // 1/R of full resolution the images were used at
  int width = 0, height = 0;              // their size (of the first view)
  PointCloud sparse;
  std::vector<double> sparse_errors_px;   // mean reprojection error per sparse point
  std::vector<int> sparse_track_lengths;
  PointCloud dense;
  std::vector<DepthMap> depth;            // per view (same order as views); empty without dense
  // statistics
  std::vector<std::size_t> features;      // per view
  std::size_t matches = 0, tracks = 0, rejected_behind = 0, rejected_error = 0, rejected_angle = 0;
  std::vector<StepTiming> timings;
  double mean_reprojection_px() const;
  double total_seconds() const;
};

TrainingGeometry build_training_geometry(const Scene& scene, const std::vector<int>& views,
                                         const TrainingGeometryOptions& options);

// The -r at which the geometry reads the images for these options: the scene's own, or the highest its
// folder offers (capped). Reads image headers only.
int geometry_resolution(const Scene& scene, const TrainingGeometryOptions& options);

// SCENE/{N}_views (N = number of training views).
std::filesystem::path training_geometry_dir(const Scene& scene, std::size_t n_views);

// Writes the files listed above (atomically each) plus the manifest that find_training_geometry checks.
void write_training_geometry(const std::filesystem::path& dir, const Scene& scene, const TrainingGeometry& g,
                             const TrainingGeometryOptions& options);

// A previously written geometry in `dir` that matches these views, resolution and options (the
// manifest records them), or nullopt.
struct CachedTrainingGeometry {
  std::filesystem::path dir, sparse_ply, dense_ply, depth_dir;
  bool has_dense = false;
};
std::optional<CachedTrainingGeometry> find_training_geometry(const std::filesystem::path& dir, const Scene& scene,
                                                             const std::vector<int>& views,
                                                             const TrainingGeometryOptions& options);

// The first of `cache_dirs` holding a matching geometry, else a new one built and written to `write_dir`.
CachedTrainingGeometry obtain_training_geometry(const Scene& scene, const std::vector<int>& views,
                                                const TrainingGeometryOptions& options,
                                                const std::vector<std::filesystem::path>& cache_dirs,
                                                const std::filesystem::path& write_dir);

// Accuracy against a reference cloud (used only to measure, e.g. the dataset's all-view SfM points):
// distance from each point to its nearest reference point; median / mean, and the reference's extent
// (diagonal of its 2nd–98th percentile box per axis).
// reference_spacing (median distance from a reference point to its nearest other reference point) tells
// what a perfect but denser cloud would score: about half the spacing between the reference points.
struct CloudAccuracy {
  double median = 0.0, mean = 0.0, reference_extent = 0.0, reference_spacing = 0.0;
  double median_fraction() const { return reference_extent > 0 ? median / reference_extent : 0.0; }
};
CloudAccuracy cloud_accuracy(const PointCloud& cloud, const PointCloud& reference);

}  // namespace d2gs
