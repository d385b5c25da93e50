#pragma once
// What a report needs from a training run folder (the layout `d2gs train` writes): the configuration,
// the metrics of results.json (PSNR, SSIM and, when present, LPIPS and AVGE), the training log, the final
// model and the test renders, and the Gaussian count per near/middle/far depth layer.
#include <cstddef>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "d2gs/model/gaussians.hpp"

namespace d2gs::report {

// train_log.jsonl as columns. A resumed run appends from its checkpoint on, so records whose iteration
// does not increase replace the ones they repeat: the curves show what the final model went through.
struct TrainLog {
  std::vector<double> iteration, loss, gaussians, elapsed_s;
  std::vector<double> test_iteration, test_psnr, test_ssim;
};
// Throws d2gs::Error naming the file and line for a line that is not a JSON object.
TrainLog read_train_log(const std::filesystem::path& path);

// Metric name ("PSNR", "SSIM", "LPIPS", "AVGE") → value; only numeric entries are kept, so a key whose
// value is a note ("skipped: ...") counts as unavailable.
using Metrics = std::map<std::string, double>;
// The mean metrics of a results.json object (its "mean" object, plus numeric top-level lpips/avge keys).
Metrics mean_metrics(const nlohmann::json& results);
// Per test view (name → metrics), from "per_view".
std::map<std::string, Metrics> view_metrics(const nlohmann::json& results);
// The metric names reported, in the paper's order, followed by any other.
std::vector<std::string> metric_order(const std::vector<std::string>& present);
// True for the metrics where lower is better (LPIPS, AVGE, IMR).
bool lower_is_better(const std::string& metric);

// Gaussians per depth layer w.r.t. a reference camera: depth is the view-space z of each mean; the
// layer limits are the depth tertiles (ranks ⌊0.33·N⌋, ⌊0.67·N⌋) of a boundary set (the run's initial
// points, the same for every method started from the same cloud), so layers mean the same region of
// space for every model compared. Means at z ≤ 0 are counted as behind the camera.
struct LayerCounts {
  std::size_t near = 0, middle = 0, far = 0, behind = 0;
  double near_limit = 0, far_limit = 0;  // near: z < near_limit; far: z ≥ far_limit
  std::string boundary;                  // where the limits come from
  std::string camera;                    // the reference camera
};

struct ReferenceCamera {
  std::string name;
  double position[3] = {0, 0, 0};
  double forward[3] = {0, 0, 1};  // camera z axis in world coordinates
  double depth(const float* x) const;
};
// Tertile limits of the depths (> 0) of `points` (xyz triples); throws when no point is in front.
std::pair<double, double> tertile_limits(const std::vector<float>& xyz, const ReferenceCamera& camera);
LayerCounts count_layers(const Gaussians& model, const ReferenceCamera& camera, std::pair<double, double> limits);

struct TestView {
  std::string name;  // file stem
  std::filesystem::path render, gt;
};

struct RunData {
  std::filesystem::path dir;
  nlohmann::json config;   // config.json (null when absent)
  nlohmann::json results;  // results.json (null when absent: the run did not finish)
  TrainLog log;
  int iteration = -1;  // highest point_cloud/iteration_N holding a point_cloud.ply, -1 when none
  std::filesystem::path ply;
  std::vector<TestView> views;  // test/ours_N/{renders,gt}/*.png pairs of the final iteration
  std::optional<LayerCounts> layers;
  std::string layers_note;  // why there are no layer counts, when there are none

  std::string method() const;  // "3dgs", ... from results.json or config.json, or "?"
};

struct RunLoadOptions {
  bool layers = true;  // read the final PLY and count Gaussians per depth layer
};
// Reads a run folder. Throws d2gs::Error when `dir` holds no config.json (not a run) or a file is
// malformed; a run without results or model still loads (the report shows what there is).
RunData load_run(const std::filesystem::path& dir, const RunLoadOptions& options = {});
// The first test camera of a run (cameras.json entry whose global_index is the first test view of
// config.json's split; else the first test camera listed), or nullopt when cameras.json is absent.
std::optional<ReferenceCamera> reference_camera(const std::filesystem::path& dir, const nlohmann::json& config);

}  // namespace d2gs::report
