#pragma once
// The files of a training run's folder beside the models, checkpoints and train_log.jsonl
// (docs/training.md, "Outputs"): config.json, cameras.json and results.json.
#include <cstddef>
#include <filesystem>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "d2gs/eval/evaluate.hpp"
#include "d2gs/scene/scene.hpp"
#include "d2gs/scene/split.hpp"
#include "d2gs/train/config.hpp"

namespace d2gs {

// MODEL/config.json: every option (train/options.cpp) and what the run made of them, the keys of
// kRecordedKeys: the split, the scene extent, the images folder, whether the initial points are an oracle, and
// the backend --device chose.
void write_run_config(const std::filesystem::path& model_dir, const TrainConfig& cfg, const Scene& scene,
                      const Split& split, float scene_extent, bool init_is_oracle, render::Device device_used);

// MODEL/cameras.json: the training then the test cameras in the 3DGS format (position, camera-to-world
// rotation, fx, fy), each with its global image index.
void write_cameras_json(const std::filesystem::path& model_dir, const Scene& scene, const Split& split);

// What results.json records beside the metrics of the test views.
struct RunResults {
  std::string method;
  int iteration = 0;
  std::size_t gaussians = 0;
  bool init_is_oracle = false;
  std::optional<double> train_seconds;  // d2gs train's; d2gs eval keeps the recorded one of the same iteration
  std::string device;                   // the backend that rendered the test views ("cpu", "cuda"); empty: not recorded
};
// MODEL/results.json: `summary` (evaluate.hpp's to_json), `run`, and the scene's image source and folder
// (what the views were scored against). Returns what it wrote.
nlohmann::json write_results_json(const std::filesystem::path& model_dir, const EvalSummary& summary,
                                  const Scene& scene, const RunResults& run);

}  // namespace d2gs
