// d2gs init: initial geometry (sparse SIFT triangulation, dense stereo + fusion, depth priors) from the
// training views of a scene, and nothing else (method.md §3).
#include <algorithm>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "cli/commands.hpp"
#include "cli/scene_flags.hpp"
#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/file_lock.hpp"
#include "d2gs/geometry/training_geometry.hpp"
#include "d2gs/model/ply.hpp"
#include "d2gs/scene/scene.hpp"
#include "d2gs/scene/split.hpp"

namespace d2gs::cli {
namespace {

struct InitOptions {
  SceneFlags scene;
  std::string output;
  bool no_dense = false;
  bool oracle_accuracy = false;
  std::string dense_method = "patchmatch", geometry_resolution = "auto", compare_cloud;
  int dense_stride = 0;  // 0: each method's default
  TrainingGeometryOptions geometry;
};

}  // namespace

Run add_init_command(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "init", "Initial geometry from the training views only: SIFT triangulation, stereo depth, fused cloud");
  cmd->footer(
      "Writes DIR/sparse/points3D.ply, DIR/dense/fused.ply, DIR/depth/NAME.npy (float32 H×W camera-space depth,\n"
      "0 = invalid; usable as `d2gs train --dafe-prior DIR/depth --dafe-prior-kind depth`), DIR/depth/NAME_valid.png\n"
      "and DIR/init.json, with DIR = SCENE/{N}_views unless -o is given. Only the training views are read.\n"
      "PatchMatch (default): multi-view stereo (COLMAP-like, on the CPU) and fusion of the depth and normal maps,\n"
      "at the highest resolution of the scene folder (depth maps at that size; fused.ply with normals);\n"
      "--dense-method sgbm runs at the training resolution.\n"
      "Example: d2gs init -s ../shared/data/nerf_llff_data/fern --n-views 3 -r 8 -o out/fern_init");
  auto o = std::make_shared<InitOptions>();
  add_scene_flags(*cmd, o->scene, SplitFlags::All);
  add_option(*cmd, "-o,--output", o->output, "Output folder (default: SCENE/{N}_views)");
  add_option(*cmd, "--seed", o->geometry.seed, "Seed of the random choices (subsampling of large dense clouds)");
  add_option(*cmd, "--max-features", o->geometry.max_features, "SIFT keypoints per view");
  add_option(*cmd, "--sift-contrast", o->geometry.sift_contrast_threshold,
             "SIFT contrast threshold (lower: more keypoints in weak texture)");
  add_option(*cmd, "--match-ratio", o->geometry.match.ratio, "Lowe's ratio test threshold");
  cmd->add_flag("--guided-matching", o->geometry.match.guided,
                "Search descriptors only along the epipolar lines (more points, more outliers) instead of over the "
                "whole image followed by the epipolar filter");
  add_option(*cmd, "--epipolar-px", o->geometry.match.epipolar_px,
             "Epipolar filter threshold in pixels (≤ 0: 0.4 % of the image diagonal)");
  add_option(*cmd, "--max-reprojection-px", o->geometry.triangulation.max_reprojection_px,
             "Largest reprojection error of a triangulated point");
  add_option(*cmd, "--min-angle", o->geometry.triangulation.min_angle_deg, "Smallest triangulation angle (degrees)");
  cmd->add_flag("--no-dense", o->no_dense, "Sparse points only (no stereo, no depth maps)");
  add_option(*cmd, "--dense-method", o->dense_method,
             "'patchmatch' (default: PatchMatch multi-view stereo with geometric consistency and COLMAP-like "
             "fusion, at the highest resolution of the scene folder) or 'sgbm' (rectified semi-global "
             "matching between neighbouring views at the training resolution: seconds instead of a minute "
             "or two, about 1.5 dB less on fern)")
      ->check(CLI::IsMember({"sgbm", "patchmatch"}));
  add_option(*cmd, "--geometry-resolution", o->geometry_resolution,
             "Images the geometry is computed from: 'training' (-r), 'highest' (the largest image folder, "
             "capped by --max-image-size) or 'auto' (default: highest for patchmatch, training for sgbm)")
      ->check(CLI::IsMember({"auto", "training", "highest"}));
  add_option(*cmd, "--max-image-size", o->geometry.max_image_size,
             "Cap on the longest image side at the highest resolution: the folder is divided by 2, 4, 8 until it "
             "fits (≤ 0: no cap)")
      ->capture_default_str();
  add_option(*cmd, "--stereo-neighbors", o->geometry.stereo_neighbors,
             "SGBM: stereo partners of each view (nearest centres)");
  add_option(*cmd, "--fusion-tolerance", o->geometry.fusion.relative_tolerance,
             "SGBM: relative depth difference within which two views agree");
  add_option(*cmd, "--dense-stride", o->dense_stride,
             "Pixel stride of the fused cloud (default: 4 for sgbm; patchmatch: every point whose first pixel "
             "lies on this grid, default 3)");
  auto& pm = o->geometry.patch_match;
  add_option(*cmd, "--pm-levels", pm.levels, "PatchMatch: pyramid levels (1: full size only)")->capture_default_str();
  add_option(*cmd, "--pm-iterations", pm.iterations, "PatchMatch: red-black iterations at the coarsest level")
      ->capture_default_str();
  add_option(*cmd, "--pm-fine-iterations", pm.fine_iterations, "PatchMatch: refining iterations at each finer level")
      ->capture_default_str();
  add_option(*cmd, "--pm-geometric-iterations", pm.geometric_iterations,
             "PatchMatch: iterations of the geometric-consistency stage (0: none)")
      ->capture_default_str();
  add_option(*cmd, "--pm-window-radius", pm.window_radius, "PatchMatch: NCC window radius")->capture_default_str();
  add_option(*cmd, "--pm-window-step", pm.window_step, "PatchMatch: NCC window sampling step")->capture_default_str();
  add_option(*cmd, "--pm-min-consistent", pm.filter_min_consistent,
             "PatchMatch: source views that must agree for a depth to be kept (0: no filter)")
      ->capture_default_str();
  add_option(*cmd, "--pm-filter-min-angle", pm.filter_min_triangulation_angle_deg,
             "PatchMatch: smallest triangulation angle (degrees) of a source that confirms a depth (COLMAP's "
             "filter_min_triangulation_angle; 0: any angle, as COLMAP before its fix of 2026-02 effectively "
             "filtered)")
      ->capture_default_str();
  add_option(*cmd, "--pm-filter-geom-px", pm.filter_geom_max_px,
             "PatchMatch: largest forward-backward reprojection error (pixels) of a source that confirms a "
             "depth (COLMAP's filter_geom_consistency_max_cost)")
      ->capture_default_str();
  add_option(*cmd, "--pm-filter-min-ncc", pm.filter_min_ncc,
             "PatchMatch: smallest NCC of a source that confirms a depth (COLMAP's filter_min_ncc)")
      ->capture_default_str();
  add_option(*cmd, "--pm-filter-min-distinctiveness", pm.filter_min_distinctiveness,
             "PatchMatch: smallest rise of a confirming source's cost (1 - NCC) when the match moves "
             "--pm-filter-distinct-px either way along its epipolar line (0: off; ours, not COLMAP's): drops "
             "depths the images do not determine (no texture across the epipolar line)")
      ->capture_default_str();
  add_option(*cmd, "--pm-filter-distinct-px", pm.filter_distinct_shift_px,
             "PatchMatch: the shift (pixels) of the distinctiveness test (the window radius)")
      ->capture_default_str();
  cmd->add_flag("--pm-filter-distinct-aperture", pm.filter_distinct_aperture,
                "PatchMatch: the distinctiveness test drops a depth only where the window has structure across "
                "the epipolar line (its cost also rises by the threshold when the match moves the same shift "
                "perpendicular to the line: the aperture problem), not where it is flat in every direction");
  add_option(*cmd, "--pm-filter-min-uniqueness", pm.filter_min_uniqueness,
             "PatchMatch: smallest margin (in 1 - NCC) by which a confirming source's match must beat every "
             "other match on its epipolar line more than two window radii away (0: off; ours, not COLMAP's): "
             "drops depths that a repeated pattern, a reflection or a uniform region leaves ambiguous")
      ->capture_default_str();
  add_option(*cmd, "--pm-filter-uniqueness-step", pm.filter_uniqueness_step,
             "PatchMatch: the uniqueness test's sampling interval along the epipolar line, in window radii")
      ->capture_default_str();
  add_option(*cmd, "--fusion-min-pixels", o->geometry.patch_match_fusion.min_pixels,
             "PatchMatch fusion: pixels (across views) a fused point needs")
      ->capture_default_str();
  add_option(*cmd, "--fusion-max-normal", o->geometry.patch_match_fusion.max_normal_deg,
             "PatchMatch fusion: largest angle (degrees) between a pixel's normal and the point's first "
             "pixel's (COLMAP's max_normal_error)")
      ->capture_default_str();
  add_option(*cmd, "--fusion-max-depth-error", o->geometry.patch_match_fusion.max_relative_depth,
             "PatchMatch fusion: largest relative depth difference of a pixel to the point (COLMAP's "
             "max_depth_error)")
      ->capture_default_str();
  add_option(*cmd, "--fusion-max-reprojection-px", o->geometry.patch_match_fusion.max_reprojection_px,
             "PatchMatch fusion: largest reprojection error (pixels) of the point into a joining pixel "
             "(COLMAP's max_reproj_error)")
      ->capture_default_str();
  add_option(*cmd, "--fusion-max-color-difference", o->geometry.patch_match_fusion.max_color_difference,
             "PatchMatch fusion: drop a fused point whose colour differs from the (blurred) image by more than "
             "this mean absolute RGB difference in a view where no surface hides it (0: off; ours, not "
             "COLMAP's; SGBM ignores it: docs/training.md)")
      ->capture_default_str();
  add_option(*cmd, "--compare-cloud", o->compare_cloud,
             "Also measure the dense cloud against this PLY (e.g. another pipeline's fused cloud): accuracy "
             "(ours to theirs) and completeness (theirs to ours), written to DIR/compare_cloud.json");
  cmd->add_flag("--oracle-accuracy", o->oracle_accuracy,
                "Also measure the clouds against the dataset's all-view SfM points (measurement only)");
  return [o]() -> int {
    const auto [scene, split] = o->scene.load();
    TrainingGeometryOptions g = o->geometry;
    g.dense = !o->no_dense;
    g.dense_method = parse_dense_method(o->dense_method);
    g.resolution = parse_geometry_resolution(o->geometry_resolution);
    if (o->dense_stride != 0) {
      if (o->dense_stride < 1) fail("--dense-stride must be at least 1, got {}", o->dense_stride);
      g.fusion.pixel_stride = o->dense_stride;
      g.patch_match_fusion.pixel_stride = o->dense_stride;
    }
    validate(g);  // every option, before the work
    if (!o->compare_cloud.empty() && !g.dense)
      fail("option --compare-cloud measures the dense cloud, which --no-dense does not make");
    if (o->oracle_accuracy && scene.sfm_points.empty())
      fail("{}: the scene has no SfM points for --oracle-accuracy to measure against", o->scene.source);
    PointCloud compare;
    if (!o->compare_cloud.empty()) compare = read_point_cloud_ply(o->compare_cloud);  // before the work
    const std::filesystem::path dir =
        o->output.empty() ? training_geometry_dir(scene, split.train.size()) : std::filesystem::path(o->output);
    check_output_folder(dir);  // before the work: a path under a file fails now
    // One init at a time into a folder, for its whole work: the checks below and the writes at the end
    // would otherwise let two of them mix their files. The folder, when made here, goes again if init fails.
    OutputSet folder;
    folder.create_folder(dir);
    const FolderWriteLock lock(dir, ".d2gs-init.lock", "d2gs init");
    // A geometry already there (an earlier d2gs init; d2gs train reuses SCENE/{N}_views) is not replaced
    // silently, as d2gs train does not replace a run.
    for (const char* file : {"init.json", "sparse/points3D.ply", "dense/fused.ply"}) {
      std::error_code ec;
      if (std::filesystem::exists(dir / file, ec))
        fail_file(dir, "already holds a training geometry ({}); remove it first, or write this one elsewhere with -o",
                  file);
    }
    // Nor are files of the names its depth maps take (a scene folder given as -o holds the demo's true
    // depth maps in depth/NAME.npy).
    if (g.dense)
      for (int v : split.train) {
        const std::string stem = std::filesystem::path(scene.cameras[static_cast<std::size_t>(v)].image_name).stem().string();
        for (const std::string& name : {stem + ".npy", stem + "_valid.png", stem + "_depth.png"}) {
          std::error_code ec;
          if (std::filesystem::exists(dir / "depth" / name, ec))
            fail_file(dir / "depth" / name, "exists, and d2gs init writes its depth maps there: write the geometry "
                      "elsewhere with -o");
        }
      }
    const TrainingGeometry geo = build_training_geometry(scene, split.train, g);
    if (g.dense && geo.dense.empty())  // nothing a training could start from: said, and nothing written
      fail("init: the stereo of the {} training views fused no point (with --dense-stride {}, the fusion options "
           "given); nothing written to {}", split.train.size(), o->dense_stride == 0 ? std::string("default") :
           std::to_string(o->dense_stride), dir.string());
    write_training_geometry(dir, scene, geo, g);
    folder.keep();
    std::string line = fmt::format("init: {} sparse points (mean reprojection error {:.3f} px)", geo.sparse.size(),
                                   geo.mean_reprojection_px());
    if (g.dense) line += fmt::format(", {} dense points", geo.dense.size());
    spdlog::info("{} in {:.2f} s → {}", line, geo.total_seconds(), dir.string());
    if (!o->compare_cloud.empty() && g.dense) {
      // Both medians as fractions of the compared cloud's extent.
      const CloudAccuracy acc = cloud_accuracy(geo.dense, compare), comp = cloud_accuracy(compare, geo.dense);
      const double extent = acc.reference_extent;
      spdlog::info("compare with {} ({} points): accuracy (ours to theirs) median {:.4g} = {:.4f} of its extent {:.4g}; "
                   "completeness (theirs to ours) median {:.4g} = {:.4f}; {} dense points of ours",
                   o->compare_cloud, compare.size(), acc.median, extent > 0 ? acc.median / extent : 0.0, extent,
                   comp.median, extent > 0 ? comp.median / extent : 0.0, geo.dense.size());
      const nlohmann::json j = {{"reference", o->compare_cloud},
                                {"reference_points", compare.size()},
                                {"points", geo.dense.size()},
                                {"extent", extent},
                                {"accuracy_median", acc.median},
                                {"accuracy_mean", acc.mean},
                                {"accuracy_fraction", extent > 0 ? acc.median / extent : 0.0},
                                {"completeness_median", comp.median},
                                {"completeness_mean", comp.mean},
                                {"completeness_fraction", extent > 0 ? comp.median / extent : 0.0}};
      write_file_atomic(dir / "compare_cloud.json", j.dump(2));
    }
    if (o->oracle_accuracy) {
      if (scene.sfm_points.empty()) fail("{}: the scene has no SfM points to measure against", o->scene.source);
      nlohmann::json acc;
      const PointCloud& sfm_points = scene.sfm_points;  // clang 14 lambdas cannot capture structured bindings
      const auto report = [&](const char* name, const PointCloud& cloud) {
        const CloudAccuracy a = cloud_accuracy(cloud, sfm_points);
        spdlog::info("accuracy ({} vs the all-view SfM ORACLE, {} points): median distance {:.4g} = {:.4f} of the "
                     "extent {:.4g}; mean {:.4g} (the oracle's own point spacing: {:.4g})",
                     name, sfm_points.size(), a.median, a.median_fraction(), a.reference_extent, a.mean,
                     a.reference_spacing);
        acc[name] = {{"median", a.median}, {"mean", a.mean}, {"extent", a.reference_extent},
                     {"median_fraction", a.median_fraction()}, {"reference_spacing", a.reference_spacing},
                     {"points", cloud.size()}};
      };
      report("sparse", geo.sparse);
      if (!compare.empty()) report("compared", compare);
      if (g.dense) {
        report("dense", geo.dense);
        // Depth maps: relative error of the stereo depth at the pixels where oracle points project.
        std::vector<double> rel, signed_rel;
        for (std::size_t i = 0; i < geo.views.size(); ++i) {
          const Camera& c = scene.cameras[static_cast<std::size_t>(geo.views[i])];
          for (const auto& p : scene.sfm_points.positions) {
            const glm::dvec3 q = c.R_world_to_cam * glm::dvec3(p) + c.t_world_to_cam;
            if (!(q.z > 0)) continue;
            const double u = c.fx * q.x / q.z + c.cx, v = c.fy * q.y / q.z + c.cy;
            if (!(u >= 0 && v >= 0 && u < c.width && v < c.height)) continue;
            // The depth maps may be at a higher resolution than the cameras (--geometry-resolution).
            const DepthMap& dm = geo.depth[i];
            const int du = std::min(dm.width - 1, static_cast<int>(u * dm.width / c.width));
            const int dv = std::min(dm.height - 1, static_cast<int>(v * dm.height / c.height));
            const float d = dm.at(du, dv);
            if (d > 0) rel.push_back(std::abs(d - q.z) / q.z), signed_rel.push_back((d - q.z) / q.z);
          }
        }
        if (!rel.empty()) {
          std::sort(rel.begin(), rel.end());
          std::sort(signed_rel.begin(), signed_rel.end());
          const double med = rel[rel.size() / 2], bias = signed_rel[signed_rel.size() / 2];
          spdlog::info("accuracy (depth maps vs the ORACLE points projected into the training views): median relative "
                       "error {:.4f} (signed {:+.4f}) over {} pixels",
                       med, bias, rel.size());
          acc["depth"] = {{"median_relative_error", med}, {"median_signed_relative_error", bias}, {"pixels", rel.size()}};
        }
      }
      write_file_atomic(dir / "oracle_accuracy.json", acc.dump(2));
    }
    return 0;
  };
}

}  // namespace d2gs::cli
