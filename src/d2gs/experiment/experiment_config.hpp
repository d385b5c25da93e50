#pragma once
// An experiment file (JSON) names scenes, view counts, seeds and methods (with named variants for
// ablation rows); it expands to one training run per combination, each in its own folder
//   DIR/runs/<scene>/<views>v/<method>[-<variant>]/seed<k>
// with the run's complete training configuration. See configs/experiments/ and docs/experiments.md.
//
//   {
//     "name": "llff_fern_3views",
//     "data_root": "../shared/data",              // scene sources are relative to it (relative: to the cwd)
//     "scenes": [{"name": "fern", "source": "nerf_llff_data/fern", "scene_preset": "llff/fern"}],
//     "views": [3], "seeds": [0, 1, 2],
//     "train": {"resolution": 8, "iterations": 10000},   // keys of d2gs train's config.json, for every run
//     "methods": [{"method": "3dgs"},
//                 {"method": "d2gs", "preset": "release", "scene_preset": true},
//                 {"method": "d2gs", "variant": "no-dafe", "options": {"dafe": false}}],
//     "checkpoint_every": 1000, "keep_checkpoints": false,
//     "imr": {"enabled": true, "samples": 10000}, "report": {"max_views": -1}
//   }
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace d2gs::experiment {

struct SceneSpec {
  std::string name;    // folder name and table label
  std::string source;  // resolved path of the scene
  std::string scene_preset;  // D²GS per-scene values used by methods with "scene_preset": true
  // d2gs train config keys for this scene's runs (e.g. its resolution), over the experiment's "train" and
  // under a method's "options".
  nlohmann::json train = nlohmann::json::object();
};

struct MethodSpec {
  std::string method;   // 3dgs | dropgaussian | d2gs
  std::string variant;  // ablation row name, may be empty
  std::string preset;   // paper | release | empty
  bool use_scene_preset = false;
  std::string scene_preset;  // an explicit name (overrides the scene's)
  nlohmann::json options = nlohmann::json::object();  // config.json keys for this method only
  std::string label() const { return variant.empty() ? method : method + "-" + variant; }
};

struct ExperimentConfig {
  std::filesystem::path file;  // where it was read from (for messages)
  std::string name;
  std::string description;
  std::string data_root;
  std::vector<SceneSpec> scenes;
  std::vector<int> views;
  std::vector<std::uint64_t> seeds;
  nlohmann::json train = nlohmann::json::object();
  std::vector<MethodSpec> methods;
  int checkpoint_every = 1000;
  bool keep_checkpoints = false;
  bool imr_enabled = true;
  std::size_t imr_samples = 10000;
  int report_max_views = -1;
  nlohmann::json raw;  // the file as read
};

// Reads and checks an experiment file. `data_root_override` (when not empty) replaces "data_root".
// Throws d2gs::Error "<file>: <problem>" for malformed input.
ExperimentConfig load_experiment_config(const std::filesystem::path& file, const std::string& data_root_override = {});
ExperimentConfig parse_experiment_config(const nlohmann::json& j, const std::filesystem::path& file,
                                         const std::string& data_root_override = {});

struct RunSpec {
  int index = 0;  // position in the run list (a Slurm array task id)
  std::string scene;
  int views = 0;
  std::string label;  // method[-variant]
  std::string method, variant;
  std::uint64_t seed = 0;
  std::filesystem::path dir;  // relative to the experiment folder: runs/<scene>/<views>v/<label>/seed<k>
  std::string id() const;     // <scene>__<views>v__<label>__seed<k>: names of its log and config files
  nlohmann::json train_config;  // complete `d2gs train --config` content (model_dir is absolute)
};

// One run per scene × views × method × seed, in that nesting order. `out_dir` is the experiment folder
// (made absolute). Every run's training configuration is built and validated here: defaults, "train",
// the method's preset, scene preset, "options", then the experiment's own keys (source, model_dir,
// n_views, seed, method, checkpoints).
std::vector<RunSpec> expand_runs(const ExperimentConfig& config, const std::filesystem::path& out_dir);

// An initial cloud named by a relative path is, as a scene's source, under data_root: the absolute path.
// Keywords (dense, sparse, random, sfm-all-views), absolute paths and an empty data_root leave it as it is.
std::string resolve_init_path(const std::string& init, const std::string& data_root);

}  // namespace d2gs::experiment
