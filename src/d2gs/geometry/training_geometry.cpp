#include "d2gs/geometry/training_geometry.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/interrupt.hpp"
#include "d2gs/core/checksum.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/npy.hpp"
#include "d2gs/core/random.hpp"
#include "d2gs/geometry/depth_preview.hpp"
#include "d2gs/geometry/features.hpp"
#include "d2gs/geometry/knn.hpp"
#include "d2gs/geometry/tracks.hpp"
#include "d2gs/model/ply.hpp"

namespace d2gs {
namespace fs = std::filesystem;

namespace {

using Clock = std::chrono::steady_clock;

class StepTimer {
public:
  explicit StepTimer(std::vector<StepTiming>& out) : out_(out) {}
  double done(const std::string& step) {
    check_interrupted("while building the training views' geometry");
    const auto now = Clock::now();
    const double s = std::chrono::duration<double>(now - start_).count();
    out_.push_back({step, s});
    start_ = now;
    return s;
  }

private:
  std::vector<StepTiming>& out_;
  Clock::time_point start_ = Clock::now();
};

std::string view_list(const Scene& scene, const std::vector<int>& views) {
  std::string s;
  for (int v : views) s += (s.empty() ? "" : ", ") + scene.cameras[static_cast<std::size_t>(v)].image_name;
  return s;
}

glm::u8vec3 color_at(const Image& img, const glm::dvec2& px) {
  const int x = std::clamp(static_cast<int>(std::floor(px.x)), 0, img.width - 1);
  const int y = std::clamp(static_cast<int>(std::floor(px.y)), 0, img.height - 1);
  glm::u8vec3 c;
  for (int k = 0; k < 3; ++k)
    c[k] = static_cast<std::uint8_t>(std::lround(std::clamp(img.at(x, y, std::min(k, img.channels - 1)), 0.0f, 1.0f) * 255.0f));
  return c;
}

// Depth range of the sparse points in front of a camera: the lo and hi quantiles of camera z.
std::optional<std::pair<double, double>> sparse_depth_range(const Camera& cam, const PointCloud& sparse,
                                                            double lo = 0.02, double hi = 0.98) {
  std::vector<double> z;
  for (const auto& p : sparse.positions) {
    const glm::dvec3 q = cam.R_world_to_cam * glm::dvec3(p) + cam.t_world_to_cam;
    if (q.z > 0.0) z.push_back(q.z);
  }
  if (z.size() < 10) return std::nullopt;
  std::sort(z.begin(), z.end());
  const auto at = [&](double q) { return z[static_cast<std::size_t>(q * static_cast<double>(z.size() - 1))]; };
  return std::make_pair(at(lo), at(hi));
}

// What changes the result. Keys of PatchMatch and of a resolution other than the training one are added
// only when they apply, so that SGBM geometries written before they existed are still found.
std::string options_key(const TrainingGeometryOptions& o, int training_resolution, int geometry_res) {
  nlohmann::json j = {{"max_features", o.max_features},
                      {"sift_contrast_threshold", o.sift_contrast_threshold},
                      {"ratio", o.match.ratio},
                      {"mutual", o.match.mutual},
                      {"guided", o.match.guided},
                      {"epipolar_px", o.match.epipolar_px},
                      {"max_reprojection_px", o.triangulation.max_reprojection_px},
                      {"min_angle_deg", o.triangulation.min_angle_deg},
                      {"dense", o.dense},
                      {"stereo_neighbors", o.stereo_neighbors},
                      {"block_size", o.stereo.block_size},
                      {"relative_tolerance", o.fusion.relative_tolerance},
                      {"min_consistent_views", o.fusion.min_consistent_views},
                      {"pixel_stride", o.fusion.pixel_stride},
                      {"max_dense_points", o.max_dense_points},
                      {"seed", o.seed}};
  if (geometry_res != training_resolution) j["geometry_resolution"] = geometry_res;
  if (o.dense && o.dense_method == DenseMethod::PatchMatch) {
    const PatchMatchOptions& p = o.patch_match;
    const PatchMatchFusionOptions& f = o.patch_match_fusion;
    j["dense_method"] = to_string(o.dense_method);
    j["patch_match"] = {{"window_radius", p.window_radius},
                        {"window_step", p.window_step},
                        {"sigma_spatial", p.sigma_spatial},
                        {"sigma_color", p.sigma_color},
                        {"ncc_sigma", p.ncc_sigma},
                        {"min_triangulation_angle_deg", p.min_triangulation_angle_deg},
                        {"max_source_views", p.max_source_views},
                        {"levels", p.levels},
                        {"iterations", p.iterations},
                        {"fine_iterations", p.fine_iterations},
                        {"geometric_iterations", p.geometric_iterations},
                        {"geom_weight", p.geom_weight},
                        {"geom_max_px", p.geom_max_px},
                        {"filter_min_ncc", p.filter_min_ncc},
                        {"filter_min_triangulation_angle_deg", p.filter_min_triangulation_angle_deg},
                        {"filter_geom_max_px", p.filter_geom_max_px},
                        {"filter_min_consistent", p.filter_min_consistent}};
    // Recorded only when on, so that the inits cached before the option existed keep their key.
    if (p.filter_min_distinctiveness > 0.0)
      j["patch_match"]["filter_min_distinctiveness"] = {p.filter_min_distinctiveness, p.filter_distinct_shift_px};
    if (p.filter_min_distinctiveness > 0.0 && p.filter_distinct_aperture)
      j["patch_match"]["filter_distinct_aperture"] = true;
    if (p.filter_min_uniqueness > 0.0) j["patch_match"]["filter_min_uniqueness"] = p.filter_min_uniqueness;
    if (p.filter_uniqueness_step != 1.0) j["patch_match"]["filter_uniqueness_step"] = p.filter_uniqueness_step;
    j["patch_match_fusion"] = {{"max_reprojection_px", f.max_reprojection_px},
                               {"max_relative_depth", f.max_relative_depth},
                               {"max_normal_deg", f.max_normal_deg},
                               {"max_traversal_depth", f.max_traversal_depth},
                               {"min_pixels", f.min_pixels},
                               {"pixel_stride", f.pixel_stride}};
    // Only when on, so that the manifests written before the test existed still match.
    if (f.max_color_difference > 0) {
      j["patch_match_fusion"]["max_color_difference"] = f.max_color_difference;
      j["patch_match_fusion"]["color_visibility_margin"] = f.color_visibility_margin;
    }
  }
  return j.dump();
}

bool is_dir(const fs::path& p) {
  std::error_code ec;
  return fs::is_directory(p, ec);
}

}  // namespace

const char* to_string(DenseMethod method) { return method == DenseMethod::PatchMatch ? "patchmatch" : "sgbm"; }

DenseMethod parse_dense_method(const std::string& name) {
  if (name == "sgbm") return DenseMethod::Sgbm;
  if (name == "patchmatch") return DenseMethod::PatchMatch;
  fail("dense method must be 'sgbm' or 'patchmatch', got '{}'", name);
}

const char* to_string(GeometryResolution r) {
  switch (r) {
    case GeometryResolution::Auto: return "auto";
    case GeometryResolution::Training: return "training";
    case GeometryResolution::Highest: return "highest";
  }
  return "auto";
}

GeometryResolution parse_geometry_resolution(const std::string& name) {
  if (name == "auto") return GeometryResolution::Auto;
  if (name == "training") return GeometryResolution::Training;
  if (name == "highest") return GeometryResolution::Highest;
  fail("geometry resolution must be 'auto', 'training' or 'highest', got '{}'", name);
}

int geometry_resolution(const Scene& scene, const TrainingGeometryOptions& o) {
  GeometryResolution r = o.resolution;
  if (r == GeometryResolution::Auto)
    r = o.dense && o.dense_method == DenseMethod::PatchMatch ? GeometryResolution::Highest : GeometryResolution::Training;
  if (r == GeometryResolution::Training || scene.cameras.empty()) return scene.resolution;
  int R = 1;
  if (scene.format != SceneFormat::Blender) {
    // The largest folder: images/ (R = 1), else images_2/, images_4/, images_8/.
    R = 0;
    for (int f : {1, 2, 4, 8})
      if (is_dir(scene.root / (f == 1 ? std::string("images") : fmt::format("images_{}", f)))) {
        R = f;
        break;
      }
    if (R == 0) return scene.resolution;
  }
  // The cap: sizes scale with 1/R from the scene's own (read from the image headers when it was loaded).
  const Camera& c = scene.cameras.front();
  const double longest = static_cast<double>(std::max(c.width, c.height)) * scene.resolution;  // at R = 1
  while (o.max_image_size > 0 && R < 8 && longest / R > o.max_image_size) R *= 2;
  return R;
}

double TrainingGeometry::mean_reprojection_px() const {
  if (sparse_errors_px.empty()) return 0.0;
  return std::accumulate(sparse_errors_px.begin(), sparse_errors_px.end(), 0.0) /
         static_cast<double>(sparse_errors_px.size());
}

double TrainingGeometry::total_seconds() const {
  double s = 0.0;
  for (const auto& t : timings) s += t.seconds;
  return s;
}

namespace {
void dense_patch_match(TrainingGeometry& g, const std::vector<const Camera*>& cams,
                       const std::vector<const Image*>& images, const TrainingGeometryOptions& options,
                       StepTimer& timer);
void dense_sgbm(TrainingGeometry& g, const std::vector<const Camera*>& cams, const std::vector<Image>& images,
                const TrainingGeometryOptions& options, StepTimer& timer);
}  // namespace

TrainingGeometry build_training_geometry(const Scene& scene, const std::vector<int>& views,
                                         const TrainingGeometryOptions& options) {
  TrainingGeometry g;
  g.views = views;
  if (views.size() < 2)
    fail_file(scene.root, "geometry from the training views needs at least 2 views, got {}", views.size());
  for (int v : views)
    if (v < 0 || static_cast<std::size_t>(v) >= scene.cameras.size())
      fail_file(scene.root, "training view {} is out of range", v);
  const std::size_t n = views.size();
  StepTimer timer(g.timings);
  // The images at the geometry's resolution: the same scene read at another -r, with the given poses.
  g.geometry_resolution = geometry_resolution(scene, options);
  Scene rescaled;
  const Scene* gs = &scene;
  if (g.geometry_resolution != scene.resolution) {
    SceneLoadOptions lo;
    lo.resolution = g.geometry_resolution;
    lo.background = scene.background;
    lo.image_source = scene.image_source;
    rescaled = load_scene(scene.root, lo);
    if (rescaled.cameras.size() != scene.cameras.size())
      fail_file(scene.root, "has {} images at 1/{} resolution but {} at 1/{}", rescaled.cameras.size(),
                g.geometry_resolution, scene.cameras.size(), scene.resolution);
    for (int v : views) {
      Camera& c = rescaled.cameras[static_cast<std::size_t>(v)];
      c.R_world_to_cam = scene.cameras[static_cast<std::size_t>(v)].R_world_to_cam;
      c.t_world_to_cam = scene.cameras[static_cast<std::size_t>(v)].t_world_to_cam;
    }
    gs = &rescaled;
  }
  std::vector<const Camera*> cams;
  for (int v : views) cams.push_back(&gs->cameras[static_cast<std::size_t>(v)]);
  g.width = cams[0]->width;
  g.height = cams[0]->height;

  // Images (training views only) and SIFT.
  std::vector<Image> images(n);
  for (std::size_t i = 0; i < n; ++i) images[i] = load_image(*gs, views[i]);
  std::vector<const Image*> image_ptrs;
  for (const auto& im : images) image_ptrs.push_back(&im);
  spdlog::info("init: read {} training views ({}) at {}x{} (1/{} resolution) in {:.2f} s", n, view_list(scene, views),
               g.width, g.height, g.geometry_resolution, timer.done("read images"));
  std::vector<ViewFeatures> features(n);
#pragma omp parallel for schedule(dynamic)
  for (std::ptrdiff_t i = 0; i < static_cast<std::ptrdiff_t>(n); ++i)
    features[static_cast<std::size_t>(i)] = detect_sift(images[static_cast<std::size_t>(i)], options.max_features,
                                                           options.sift_contrast_threshold);
  for (const auto& f : features) g.features.push_back(f.size());
  spdlog::info("init: SIFT: {} keypoints in {} views ({:.2f} s)",
               std::accumulate(g.features.begin(), g.features.end(), std::size_t{0}), n, timer.done("sift"));

  // Matching between every pair, epipolar filter from the poses.
  std::vector<PairMatches> pairs;
  for (std::size_t a = 0; a < n; ++a)
    for (std::size_t b = a + 1; b < n; ++b) pairs.push_back({static_cast<int>(a), static_cast<int>(b), {}});
  std::size_t raw_matches = 0;
#pragma omp parallel for schedule(dynamic) reduction(+ : raw_matches)
  for (std::ptrdiff_t k = 0; k < static_cast<std::ptrdiff_t>(pairs.size()); ++k) {
    auto& p = pairs[static_cast<std::size_t>(k)];
    const auto ia = static_cast<std::size_t>(p.view_a), ib = static_cast<std::size_t>(p.view_b);
    double threshold = options.match.epipolar_px;
    if (!(threshold > 0.0)) threshold = 0.004 * std::hypot(cams[ia]->width, cams[ia]->height);
    if (options.match.guided) {
      p.matches = match_guided(features[ia], features[ib], *cams[ia], *cams[ib], options.match, threshold);
      raw_matches += p.matches.size();
    } else {
      const auto raw = match_descriptors(features[ia], features[ib], options.match);
      raw_matches += raw.size();
      p.matches = filter_epipolar(raw, features[ia], features[ib], *cams[ia], *cams[ib], threshold);
    }
  }
  for (const auto& p : pairs) g.matches += p.matches.size();
  if (options.match.guided)
    spdlog::info("init: matching {} pairs along their epipolar lines: {} matches ({:.2f} s)", pairs.size(), g.matches,
                 timer.done("matching"));
  else
    spdlog::info("init: matching {} pairs: {} ratio/mutual matches, {} after the epipolar filter ({:.2f} s)",
                 pairs.size(), raw_matches, g.matches, timer.done("matching"));

  // Tracks and triangulation.
  TrackStats ts;
  const auto tracks = build_tracks(g.features, pairs, &ts);
  g.tracks = tracks.size();
  std::vector<TriangulatedPoint> tri(tracks.size());
#pragma omp parallel for schedule(dynamic, 64)
  for (std::ptrdiff_t k = 0; k < static_cast<std::ptrdiff_t>(tracks.size()); ++k) {
    std::vector<Observation> obs;
    for (const auto& o : tracks[static_cast<std::size_t>(k)])
      obs.push_back({cams[static_cast<std::size_t>(o.view)],
                     features[static_cast<std::size_t>(o.view)].keypoints[static_cast<std::size_t>(o.feature)]});
    tri[static_cast<std::size_t>(k)] = triangulate(obs, options.triangulation);
  }
  for (std::size_t k = 0; k < tracks.size(); ++k) {
    switch (tri[k].result) {
      case TriangulationResult::Ok: break;
      case TriangulationResult::BehindCamera:
      case TriangulationResult::Degenerate: ++g.rejected_behind; continue;
      case TriangulationResult::ReprojectionError: ++g.rejected_error; continue;
      case TriangulationResult::SmallAngle: ++g.rejected_angle; continue;
    }
    glm::dvec3 rgb(0.0);
    for (const auto& o : tracks[k])
      rgb += glm::dvec3(color_at(images[static_cast<std::size_t>(o.view)],
                                 features[static_cast<std::size_t>(o.view)].keypoints[static_cast<std::size_t>(o.feature)]));
    rgb /= static_cast<double>(tracks[k].size());
    g.sparse.positions.emplace_back(glm::vec3(tri[k].position));
    g.sparse.colors.emplace_back(glm::u8vec3(glm::round(rgb)));
    g.sparse_errors_px.push_back(tri[k].mean_error_px);
    g.sparse_track_lengths.push_back(static_cast<int>(tracks[k].size()));
  }
  spdlog::info("init: {} tracks ({} inconsistent dropped) → {} points, mean reprojection error {:.3f} px; rejected: "
               "{} behind a camera, {} reprojection, {} small angle ({:.2f} s)",
               tracks.size(), ts.inconsistent, g.sparse.size(), g.mean_reprojection_px(), g.rejected_behind,
               g.rejected_error, g.rejected_angle, timer.done("triangulation"));
  if (g.sparse.size() < static_cast<std::size_t>(std::max(1, options.min_sparse_points)))
    fail_file(scene.root,
              "only {} points could be triangulated from the training views ({}; {} matches): the views do not "
              "overlap enough for a geometry of their own (use --init random or --init PLY)",
              g.sparse.size(), view_list(scene, views), g.matches);
  if (!options.dense) return g;
  if (options.dense_method == DenseMethod::PatchMatch) {
    dense_patch_match(g, cams, image_ptrs, options, timer);
  } else {
    dense_sgbm(g, cams, images, options, timer);
  }
  if (options.max_dense_points > 0 && g.dense.size() > options.max_dense_points) {
    // Seeded subsample, kept in the original order.
    Rng rng = Rng::stream(options.seed, "dense-subsample");
    std::vector<std::size_t> idx(g.dense.size());
    std::iota(idx.begin(), idx.end(), std::size_t{0});
    for (std::size_t i = 0; i < options.max_dense_points; ++i)
      std::swap(idx[i], idx[i + rng.below(idx.size() - i)]);
    idx.resize(options.max_dense_points);
    std::sort(idx.begin(), idx.end());
    g.dense = select_points(g.dense, idx);
  }
  std::size_t valid = 0, total = 0;
  for (const auto& d : g.depth) valid += d.valid_count(), total += d.depth.size();
  spdlog::info("init: fusion: {:.1f} % of the pixels have a consistent depth → {} dense points ({:.2f} s)",
               total ? 100.0 * static_cast<double>(valid) / static_cast<double>(total) : 0.0, g.dense.size(),
               timer.done("fusion"));
  return g;
}

namespace {

void dense_patch_match(TrainingGeometry& g, const std::vector<const Camera*>& cams,
                       const std::vector<const Image*>& images, const TrainingGeometryOptions& options,
                       StepTimer& timer) {
  // Depth ranges as COLMAP's: 1st and 99th percentiles of the sparse points' depths, stretched by 25 %.
  std::vector<std::pair<double, double>> ranges;
  for (const Camera* c : cams) {
    const auto r = sparse_depth_range(*c, g.sparse, 0.01, 0.99);
    if (!r) fail("init: fewer than 10 sparse points lie in front of {}: no depth range for its stereo", c->image_name);
    ranges.emplace_back(r->first * 0.75, r->second * 1.25);
  }
  PatchMatchOptions pm = options.patch_match;
  pm.seed = options.seed;
  const auto maps = patch_match_stereo(cams, images, ranges, pm);
  std::size_t valid = 0;
  for (const auto& m : maps) valid += m.depth.valid_count();
  spdlog::info("init: PatchMatch stereo on {} views at {}x{}: {} filtered depths ({:.2f} s)", cams.size(),
               cams[0]->width, cams[0]->height, valid, timer.done("stereo"));
  PatchMatchFusionStats stats;
  g.dense = fuse_patch_match(cams, images, maps, options.patch_match_fusion, &stats);
  if (options.patch_match_fusion.max_color_difference > 0)
    spdlog::info("init: fusion: the colour test (max difference {:.2f}) removed {} of {} fused points",
                 options.patch_match_fusion.max_color_difference, stats.color_dropped, stats.fused);
  g.depth.clear();
  for (const auto& m : maps) g.depth.push_back(m.depth);
}

void dense_sgbm(TrainingGeometry& g, const std::vector<const Camera*>& cams, const std::vector<Image>& images,
                const TrainingGeometryOptions& options, StepTimer& timer) {
  const std::size_t n = cams.size();
  // Rectified SGBM between each view and its nearest views.
  std::vector<std::pair<std::size_t, std::size_t>> stereo_pairs;
  for (std::size_t a = 0; a < n; ++a) {
    std::vector<std::size_t> order;
    for (std::size_t b = 0; b < n; ++b)
      if (b != a) order.push_back(b);
    std::stable_sort(order.begin(), order.end(), [&](std::size_t x, std::size_t y) {
      return glm::length(cams[x]->center_world() - cams[a]->center_world()) <
             glm::length(cams[y]->center_world() - cams[a]->center_world());
    });
    order.resize(std::min<std::size_t>(order.size(), static_cast<std::size_t>(std::max(1, options.stereo_neighbors))));
    for (std::size_t b : order) stereo_pairs.emplace_back(std::min(a, b), std::max(a, b));
  }
  std::sort(stereo_pairs.begin(), stereo_pairs.end());
  stereo_pairs.erase(std::unique(stereo_pairs.begin(), stereo_pairs.end()), stereo_pairs.end());
  std::vector<StereoPairDepth> pair_depth(stereo_pairs.size());
  std::vector<std::string> pair_errors(stereo_pairs.size());
#pragma omp parallel for schedule(dynamic)
  for (std::ptrdiff_t k = 0; k < static_cast<std::ptrdiff_t>(stereo_pairs.size()); ++k) {
    const auto [a, b] = stereo_pairs[static_cast<std::size_t>(k)];
    const auto range = sparse_depth_range(*cams[a], g.sparse);
    if (!range) {
      pair_errors[static_cast<std::size_t>(k)] = "too few sparse points in front of the camera";
      continue;
    }
    try {
      pair_depth[static_cast<std::size_t>(k)] =
          stereo_pair_depth(*cams[a], images[a], *cams[b], images[b], range->first, range->second, options.stereo);
    } catch (const Error& e) {
      pair_errors[static_cast<std::size_t>(k)] = e.what();
    }
  }
  std::vector<std::vector<const DepthMap*>> candidates(n);
  for (std::size_t k = 0; k < stereo_pairs.size(); ++k) {
    const auto [a, b] = stereo_pairs[k];
    if (!pair_errors[k].empty()) {
      spdlog::warn("init: stereo {} / {} skipped: {}", cams[a]->image_name, cams[b]->image_name, pair_errors[k]);
      continue;
    }
    spdlog::debug("init: stereo {} / {}: disparities {}..{}, {} + {} depths", cams[a]->image_name, cams[b]->image_name,
                  pair_depth[k].min_disparity, pair_depth[k].min_disparity + pair_depth[k].num_disparities,
                  pair_depth[k].depth_a.valid_count(), pair_depth[k].depth_b.valid_count());
    candidates[a].push_back(&pair_depth[k].depth_a);
    candidates[b].push_back(&pair_depth[k].depth_b);
  }
  spdlog::info("init: stereo on {} pairs ({:.2f} s)", stereo_pairs.size(), timer.done("stereo"));
  std::vector<DepthMap> merged(n);
  for (std::size_t i = 0; i < n; ++i) {
    if (candidates[i].empty()) {
      merged[i].width = cams[i]->width;
      merged[i].height = cams[i]->height;
      merged[i].depth.assign(static_cast<std::size_t>(cams[i]->width) * cams[i]->height, 0.0f);
    } else {
      merged[i] = merge_depth_candidates(candidates[i], options.fusion.relative_tolerance);
    }
  }
  g.depth = filter_consistent_depths(cams, merged, options.fusion);
  std::vector<const Image*> image_ptrs;
  for (const auto& im : images) image_ptrs.push_back(&im);
  g.dense = fuse_depth_maps(cams, image_ptrs, g.depth, options.fusion.pixel_stride);
}

}  // namespace

namespace {

// What the geometry was built from, view by view: the CRC-32 of each image file and the camera centre. A
// scene regenerated or re-processed under the same image names (d2gs demo --seed, new poses) is then not
// taken for the one its cached geometry saw.
nlohmann::json view_fingerprints(const Scene& scene, const std::vector<int>& views) {
  nlohmann::json out = nlohmann::json::array();
  for (int v : views) {
    const Camera& cam = scene.cameras[static_cast<std::size_t>(v)];
    const glm::dvec3 c = cam.center_world();
    out.push_back({{"crc32", crc32(read_file(cam.image_path))}, {"centre", {c.x, c.y, c.z}}});
  }
  return out;
}

// "" when `recorded` (a manifest's "view_fingerprints") matches the scene's views now, else what differs.
std::string fingerprint_difference(const nlohmann::json& recorded, const nlohmann::json& now,
                                   const nlohmann::json& names) {
  if (!recorded.is_array() || recorded.size() != now.size()) return "another number of views";
  for (std::size_t k = 0; k < now.size(); ++k) {
    const auto& r = recorded[k];
    if (!r.is_object() || r.value("crc32", nlohmann::json()) != now[k]["crc32"])
      return fmt::format("the image {} has changed", names[k].get<std::string>());
    const auto& c = r.value("centre", nlohmann::json());
    for (std::size_t i = 0; i < 3; ++i) {
      const double is = now[k]["centre"][i].get<double>();
      if (!c.is_array() || c.size() != 3 || !c[i].is_number() ||
          !(std::abs(c[i].get<double>() - is) <= 1e-6 * (1.0 + std::abs(is))))
        return fmt::format("the camera of {} has moved", names[k].get<std::string>());
    }
  }
  return "";
}

}  // namespace

void validate(const TrainingGeometryOptions& o) {
  // v finite, above lo (or at it unless lo_open) and below hi (or at it unless hi_open).
  const auto in = [](double v, double lo, bool lo_open, double hi, bool hi_open, const char* flag, const char* range) {
    if (!std::isfinite(v) || (lo_open ? !(v > lo) : !(v >= lo)) || (hi_open ? !(v < hi) : !(v <= hi)))
      fail("option {} must be {} (got {})", flag, range, v);
  };
  if (o.max_features < 1) fail("option --max-features must be ≥ 1 (got {})", o.max_features);
  in(o.sift_contrast_threshold, 0.0, true, 1.0, false, "--sift-contrast", "in (0, 1]");
  in(o.match.ratio, 0.0, true, 1.0, false, "--match-ratio", "in (0, 1]");
  in(o.match.epipolar_px, -1e300, false, 1e6, false, "--epipolar-px", "a number of pixels (≤ 0: automatic)");
  in(o.triangulation.max_reprojection_px, 0.0, true, 1e6, false, "--max-reprojection-px", "> 0");
  in(o.triangulation.min_angle_deg, 0.0, false, 90.0, true, "--min-angle", "in [0, 90) degrees");
  if (o.stereo_neighbors < 1) fail("option --stereo-neighbors must be ≥ 1 (got {})", o.stereo_neighbors);
  in(o.fusion.relative_tolerance, 0.0, true, 1.0, false, "--fusion-tolerance", "in (0, 1]");
  validate(o.patch_match);
  validate(o.patch_match_fusion);
}

fs::path training_geometry_dir(const Scene& scene, std::size_t n_views) {
  return scene.root / fmt::format("{}_views", n_views);
}

void write_training_geometry(const fs::path& dir, const Scene& scene, const TrainingGeometry& g,
                             const TrainingGeometryOptions& options) {
  // The manifest goes first and comes last, so that files of two geometries are never taken for one; a
  // write that fails part-way takes back what it wrote, so that a rerun finds the folder as it was.
  std::error_code ec;
  fs::remove(dir / "init.json", ec);
  OutputSet outputs;
  outputs.create_folder(dir / "sparse");
  write_point_cloud_ply(outputs.file(dir / "sparse" / "points3D.ply"), g.sparse);
  nlohmann::json depth_files = nlohmann::json::array();
  if (!g.depth.empty()) {
    outputs.create_folder(dir / "dense");
    outputs.create_folder(dir / "depth");
    write_point_cloud_ply(outputs.file(dir / "dense" / "fused.ply"), g.dense);
    const auto inverse_range = inverse_depth_range(g.depth);
    for (std::size_t i = 0; i < g.views.size(); ++i) {
      check_interrupted("while writing the training views' geometry");
      const Camera& cam = scene.cameras[static_cast<std::size_t>(g.views[i])];
      const std::string stem = fs::path(cam.image_name).stem().string();
      const DepthMap& d = g.depth[i];
      write_npy_f32(outputs.file(dir / "depth" / (stem + ".npy")),
                    {static_cast<std::size_t>(d.height), static_cast<std::size_t>(d.width)}, d.depth);
      Image mask(d.width, d.height, 1);
      for (std::size_t p = 0; p < d.depth.size(); ++p) mask.pixels[p] = d.depth[p] > 0.0f ? 1.0f : 0.0f;
      write_image(outputs.file(dir / "depth" / (stem + "_valid.png")), mask);
      write_image(outputs.file(dir / "depth" / (stem + "_depth.png")), depth_preview(d, inverse_range));
      depth_files.push_back(stem + ".npy");
    }
  }
  nlohmann::json names = nlohmann::json::array(), timings = nlohmann::json::object();
  for (int v : g.views) names.push_back(scene.cameras[static_cast<std::size_t>(v)].image_name);
  for (const auto& t : g.timings) timings[t.step] = t.seconds;
  nlohmann::json m = {
      {"format", "d2gs-training-geometry-1"},
      {"views", g.views},
      {"image_names", names},
      {"resolution", scene.resolution},
      {"image_source", to_string(scene.image_source)},
      {"view_fingerprints", view_fingerprints(scene, g.views)},
      {"width", scene.cameras[static_cast<std::size_t>(g.views[0])].width},
      {"height", scene.cameras[static_cast<std::size_t>(g.views[0])].height},
      {"geometry_resolution", g.geometry_resolution},
      {"geometry_width", g.width},
      {"geometry_height", g.height},
      {"dense_method", options.dense ? to_string(options.dense_method) : ""},
      {"options", options_key(options, scene.resolution, g.geometry_resolution)},
      {"sparse", "sparse/points3D.ply"},
      {"sparse_points", g.sparse.size()},
      {"mean_reprojection_px", g.mean_reprojection_px()},
      {"features", g.features},
      {"matches", g.matches},
      {"tracks", g.tracks},
      {"dense", g.depth.empty() ? "" : "dense/fused.ply"},
      {"dense_points", g.dense.size()},
      {"depth_dir", g.depth.empty() ? "" : "depth"},
      {"depth_files", depth_files},
      {"depth_kind", "depth"},
      {"timings_s", timings},
      {"total_s", g.total_seconds()}};
  write_file_atomic(dir / "init.json", m.dump(2));  // last: a manifest means the files above are complete
  outputs.keep();
}

std::optional<CachedTrainingGeometry> find_training_geometry(const fs::path& dir, const Scene& scene,
                                                             const std::vector<int>& views,
                                                             const TrainingGeometryOptions& options) {
  std::error_code ec;
  if (!fs::is_regular_file(dir / "init.json", ec)) return std::nullopt;
  try {
    const nlohmann::json m = nlohmann::json::parse(read_file(dir / "init.json"));
    nlohmann::json names = nlohmann::json::array();
    for (int v : views) names.push_back(scene.cameras[static_cast<std::size_t>(v)].image_name);
    if (m.value("format", "") != "d2gs-training-geometry-1" || m.value("views", nlohmann::json()) != nlohmann::json(views) ||
        m.value("image_names", nlohmann::json()) != names ||
        m.value("resolution", nlohmann::json()) != nlohmann::json(scene.resolution) ||
        m.value("image_source", "folder") != std::string(to_string(scene.image_source)) ||
        m.value("options", "") != options_key(options, scene.resolution, geometry_resolution(scene, options)))
      return std::nullopt;
    // Manifests written before 2026-12-02 record no fingerprints and are taken on their names as before.
    if (m.contains("view_fingerprints")) {
      const std::string why = fingerprint_difference(m["view_fingerprints"], view_fingerprints(scene, views), names);
      if (!why.empty()) {
        spdlog::warn("{}: not reused: {} since this geometry was built", dir.string(), why);
        return std::nullopt;
      }
    }
    CachedTrainingGeometry c;
    c.dir = dir;
    c.sparse_ply = dir / m.value("sparse", "sparse/points3D.ply");
    c.has_dense = !m.value("dense", "").empty();
    if (c.has_dense) {
      c.dense_ply = dir / m.value("dense", "");
      c.depth_dir = dir / m.value("depth_dir", "depth");
    }
    if (!fs::is_regular_file(c.sparse_ply, ec) || (c.has_dense && !fs::is_regular_file(c.dense_ply, ec)))
      return std::nullopt;
    return c;
  } catch (const nlohmann::json::exception&) {  // not JSON, or a key of another type
    spdlog::warn("{}: unreadable manifest, ignored", (dir / "init.json").string());
    return std::nullopt;
  }
}

CachedTrainingGeometry obtain_training_geometry(const Scene& scene, const std::vector<int>& views,
                                                const TrainingGeometryOptions& options,
                                                const std::vector<fs::path>& cache_dirs, const fs::path& write_dir) {
  for (const auto& dir : cache_dirs)
    if (auto c = find_training_geometry(dir, scene, views, options)) {
      spdlog::info("init: reusing the training-view geometry in {}", dir.string());
      return *c;
    }
  spdlog::info("init: building the geometry of the {} training views into {}", views.size(), write_dir.string());
  const TrainingGeometry g = build_training_geometry(scene, views, options);
  write_training_geometry(write_dir, scene, g, options);
  auto c = find_training_geometry(write_dir, scene, views, options);
  if (!c) fail_file(write_dir / "init.json", "geometry just written cannot be read back");
  return *c;
}

CloudAccuracy cloud_accuracy(const PointCloud& cloud, const PointCloud& reference) {
  CloudAccuracy a;
  if (cloud.empty() || reference.empty()) return a;
  const auto d = nearest_distances(&cloud.positions[0].x, cloud.size(), &reference.positions[0].x, reference.size());
  std::vector<float> s = d;
  std::nth_element(s.begin(), s.begin() + static_cast<std::ptrdiff_t>(s.size() / 2), s.end());
  a.median = s[s.size() / 2];
  a.mean = std::accumulate(d.begin(), d.end(), 0.0) / static_cast<double>(d.size());
  glm::dvec3 lo(0.0), hi(0.0);
  for (int k = 0; k < 3; ++k) {
    std::vector<float> v;
    for (const auto& p : reference.positions) v.push_back(p[k]);
    std::sort(v.begin(), v.end());
    lo[k] = v[static_cast<std::size_t>(0.02 * static_cast<double>(v.size() - 1))];
    hi[k] = v[static_cast<std::size_t>(0.98 * static_cast<double>(v.size() - 1))];
  }
  a.reference_extent = glm::length(hi - lo);
  std::vector<float> spacing = knn_mean_distance(&reference.positions[0].x, reference.size(), 1, KnnStatistic::MeanDistance);
  std::nth_element(spacing.begin(), spacing.begin() + static_cast<std::ptrdiff_t>(spacing.size() / 2), spacing.end());
  a.reference_spacing = spacing[spacing.size() / 2];
  return a;
}

}  // namespace d2gs
