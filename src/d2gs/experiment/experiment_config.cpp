#include "d2gs/experiment/experiment_config.hpp"

#include <algorithm>
#include <limits>
#include <map>
#include <set>
#include <type_traits>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/json_value.hpp"
#include "d2gs/train/config.hpp"
#include "d2gs/train/methods/registry.hpp"
#include "d2gs/train/options.hpp"
#include "d2gs/train/presets.hpp"

namespace d2gs::experiment {
namespace fs = std::filesystem;

namespace {

// Names become folder names: letters, digits, '.', '_' and '-' only, not starting with '.'.
// Letters, digits, '.', '_', '-', and no "__", which separates the parts of a run's id (RunSpec::id): a
// scene "s__3v__3dgs-v" and a variant "v__3v__3dgs" of scene "s" gave two runs one id, one log and one lock.
bool safe_name(const std::string& s) {
  if (s.empty() || s.size() > 64 || s.front() == '.' || s.find("__") != std::string::npos) return false;
  return std::all_of(s.begin(), s.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '.' || c == '_' ||
           c == '-';
  });
}

// Options the experiment sets itself for every run (or their former names), and the keys a run's
// config.json records beside its options.
constexpr const char* kReservedKeys[] = {"source", "model_path", "n_views", "seed", "method", "checkpoint_iterations"};

void check_keys(const nlohmann::json& j, std::initializer_list<const char*> allowed, const fs::path& file,
                const std::string& where) {
  for (const auto& item : j.items()) {
    const std::string& key = item.key();  // (clang 14 cannot capture a structured binding in a lambda)
    if (std::find_if(allowed.begin(), allowed.end(), [&](const char* a) { return key == a; }) == allowed.end())
      fail_file(file, "unknown key '{}' in {}", key, where);
  }
}

void check_train_keys(const nlohmann::json& j, const fs::path& file, const std::string& where) {
  if (!j.is_object()) fail_file(file, "{} must be an object of d2gs train config keys", where);
  for (const auto& [key, value] : j.items()) {
    const TrainOption* option = find_train_option(key);
    for (const char* reserved : kReservedKeys)
      if (option && option->name == reserved) fail_file(file, "{} sets '{}', which the experiment sets for each run", where, key);
    for (const char* recorded : kRecordedKeys)
      if (key == recorded) fail_file(file, "{} sets '{}', which the experiment sets for each run", where, key);
  }
  TrainConfig probe;
  try {
    update_from_json(probe, j);
  } catch (const Error& e) {
    fail_file(file, "{}: {}", where, e.what());
  }
}

template <typename T>
T get(const nlohmann::json& j, const char* key, const T& fallback, const fs::path& file, const std::string& where) {
  if (!j.contains(key)) return fallback;
  const nlohmann::json& v = j.at(key);
  const bool ok = std::is_same_v<T, bool> ? v.is_boolean() : v.is_string();
  if (!ok) fail_file(file, "{}: key '{}' has the wrong type (expected {})", where, key, std::is_same_v<T, bool> ? "true or false" : "a string");
  return v.get<T>();
}

// A number (or a list of numbers) of the experiment file, type- and range-checked (json_value.hpp).
template <typename T>
T number(const nlohmann::json& j, const char* key, T fallback, T min, T max, const fs::path& file,
         const std::string& where) {
  if (!j.contains(key)) return fallback;
  try {
    return json_number<T>(j.at(key), key, min, max);
  } catch (const Error& e) {
    fail_file(file, "{}: {}", where, e.what());
  }
}
template <typename T>
std::vector<T> number_list(const nlohmann::json& j, const char* key, T min, T max, const fs::path& file,
                           const std::string& where) {
  if (!j.contains(key)) return {};
  try {
    return json_number_list<T>(j.at(key), key, min, max);
  } catch (const Error& e) {
    fail_file(file, "{}: {}", where, e.what());
  }
}

}  // namespace

std::string RunSpec::id() const { return fmt::format("{}__{}v__{}__seed{}", scene, views, label, seed); }

ExperimentConfig load_experiment_config(const fs::path& file, const std::string& data_root_override) {
  const nlohmann::json j = read_json_file(file);
  if (j.is_object() && j.contains("format") && j.contains("config"))
    fail_file(file, "is an experiment folder's state (written by d2gs experiment), not an experiment file: give its "
                    "folder with -o and no --config, or the experiment file it was made from ({})",
              j.contains("config_file") && j["config_file"].is_string() ? j["config_file"].get<std::string>()
                                                                         : std::string("unrecorded"));
  return parse_experiment_config(j, file, data_root_override);
}

ExperimentConfig parse_experiment_config(const nlohmann::json& j, const fs::path& file,
                                         const std::string& data_root_override) {
  if (!j.is_object()) fail_file(file, "an experiment file is a JSON object");
  check_keys(j, {"name", "description", "data_root", "scenes", "views", "seeds", "train", "methods",
                 "checkpoint_every", "keep_checkpoints", "imr", "report"},
             file, "the experiment");
  ExperimentConfig c;
  c.file = file;
  c.raw = j;
  const std::string top = "the experiment";
  c.name = get<std::string>(j, "name", file.stem().string(), file, top);
  // The name goes into tables, the report and the Slurm scripts' comments: no line breaks or other control
  // characters (a newline in it became a command of the emitted script).
  if (c.name.empty() || std::any_of(c.name.begin(), c.name.end(), [](char ch) { return static_cast<unsigned char>(ch) < 0x20 || ch == 0x7f; }))
    fail_file(file, "'name' must be a non-empty line of text without control characters, got {}", nlohmann::json(c.name).dump());
  c.description = get<std::string>(j, "description", "", file, top);
  c.data_root = data_root_override.empty() ? get<std::string>(j, "data_root", "", file, top) : data_root_override;
  if (!j.contains("scenes") || !j["scenes"].is_array() || j["scenes"].empty())
    fail_file(file, "'scenes' must be a non-empty array");
  std::set<std::string> names;
  for (const auto& s : j["scenes"]) {
    if (!s.is_object()) fail_file(file, "each scene is an object with name and source");
    check_keys(s, {"name", "source", "scene_preset", "train"}, file, "a scene");
    SceneSpec spec;
    spec.source = get<std::string>(s, "source", "", file, "a scene");
    if (spec.source.empty()) fail_file(file, "a scene has no 'source'");
    spec.name = get<std::string>(s, "name", fs::path(spec.source).filename().string(), file, "scene " + spec.source);
    if (!safe_name(spec.name)) fail_file(file, "scene name '{}' must be letters, digits, '.', '_' or '-' (no '__')", spec.name);
    if (!names.insert(spec.name).second) fail_file(file, "scene name '{}' appears twice", spec.name);
    spec.scene_preset = get<std::string>(s, "scene_preset", "", file, "scene " + spec.name);
    spec.train = s.value("train", nlohmann::json::object());
    check_train_keys(spec.train, file, fmt::format("scene {}'s 'train'", spec.name));
    fs::path src = spec.source;
    if (src.is_relative() && !c.data_root.empty()) src = fs::path(c.data_root) / src;
    spec.source = fs::absolute(src).lexically_normal().string();
    c.scenes.push_back(spec);
  }
  c.views = number_list<int>(j, "views", 0, std::numeric_limits<int>::max(), file, top);
  if (c.views.empty()) fail_file(file, "'views' must list at least one view count (0 = all non-test views)");
  if (std::set<int>(c.views.begin(), c.views.end()).size() != c.views.size()) fail_file(file, "'views' repeats a value");
  c.seeds = j.contains("seeds") ? number_list<std::uint64_t>(j, "seeds", 0, std::numeric_limits<std::uint64_t>::max(), file, top)
                                : std::vector<std::uint64_t>{0};
  if (c.seeds.empty()) fail_file(file, "'seeds' must list at least one seed");
  if (std::set<std::uint64_t>(c.seeds.begin(), c.seeds.end()).size() != c.seeds.size())
    fail_file(file, "'seeds' repeats a value");
  c.train = j.value("train", nlohmann::json::object());
  check_train_keys(c.train, file, "'train'");
  if (!j.contains("methods") || !j["methods"].is_array() || j["methods"].empty())
    fail_file(file, "'methods' must be a non-empty array");
  std::set<std::string> labels;
  for (const auto& m : j["methods"]) {
    if (!m.is_object()) fail_file(file, "each method is an object with at least 'method'");
    check_keys(m, {"method", "variant", "preset", "scene_preset", "options"}, file, "a method");
    MethodSpec spec;
    spec.method = get<std::string>(m, "method", "", file, "a method");
    try {
      check_method_name(spec.method);
    } catch (const Error& e) {
      fail_file(file, "{}", e.what());
    }
    spec.variant = get<std::string>(m, "variant", "", file, "method " + spec.method);
    if (!spec.variant.empty() && !safe_name(spec.variant))
      fail_file(file, "variant name '{}' must be letters, digits, '.', '_' or '-' (no '__')", spec.variant);
    const std::string where = "method " + spec.label();
    if (!labels.insert(spec.label()).second) fail_file(file, "method '{}' appears twice (give it a variant)", spec.label());
    spec.preset = get<std::string>(m, "preset", "", file, where);
    if (!spec.preset.empty()) {
      const auto& presets = d2gs_preset_names();
      if (std::find(presets.begin(), presets.end(), spec.preset) == presets.end())
        fail_file(file, "{}: preset must be one of {} (got '{}')", where, fmt::join(presets, ", "), spec.preset);
      if (spec.method != "d2gs")
        fail_file(file, "{}: preset '{}' is a D2GS preset, but the method is {}", where, spec.preset, spec.method);
    }
    if (m.contains("scene_preset")) {
      if (m["scene_preset"].is_boolean()) spec.use_scene_preset = m["scene_preset"].get<bool>();
      else if (m["scene_preset"].is_string()) spec.scene_preset = m["scene_preset"].get<std::string>();
      else fail_file(file, "{}: scene_preset is true/false or a preset name", where);
    }
    spec.options = m.value("options", nlohmann::json::object());
    check_train_keys(spec.options, file, where + " options");
    c.methods.push_back(spec);
  }
  c.checkpoint_every = number<int>(j, "checkpoint_every", 1000, 1, std::numeric_limits<int>::max(), file, top);
  c.keep_checkpoints = get<bool>(j, "keep_checkpoints", false, file, top);
  if (j.contains("imr")) {
    const auto& imr = j["imr"];
    if (!imr.is_object()) fail_file(file, "'imr' must be an object");
    check_keys(imr, {"enabled", "samples"}, file, "'imr'");
    c.imr_enabled = get<bool>(imr, "enabled", true, file, "'imr'");
    c.imr_samples = number<std::size_t>(imr, "samples", 10000, 0, std::numeric_limits<std::size_t>::max(), file, "'imr'");
  }
  if (j.contains("report")) {
    const auto& r = j["report"];
    if (!r.is_object()) fail_file(file, "'report' must be an object");
    check_keys(r, {"max_views"}, file, "'report'");
    c.report_max_views = number<int>(r, "max_views", -1, -1, std::numeric_limits<int>::max(), file, "'report'");
  }
  return c;
}

std::string resolve_init_path(const std::string& init, const std::string& data_root) {
  if (init == "dense" || init == "sparse" || init == "random" || init == "sfm-all-views" || init.empty() ||
      !fs::path(init).is_relative() || data_root.empty())
    return init;
  return fs::absolute(fs::path(data_root) / init).lexically_normal().string();
}

std::vector<RunSpec> expand_runs(const ExperimentConfig& config, const fs::path& out_dir) {
  const fs::path root = fs::absolute(out_dir).lexically_normal();
  std::vector<RunSpec> runs;
  for (const auto& scene : config.scenes)
    for (int views : config.views)
      for (const auto& m : config.methods)
        for (std::uint64_t seed : config.seeds) {
          RunSpec r;
          r.index = static_cast<int>(runs.size());
          r.scene = scene.name;
          r.views = views;
          r.label = m.label();
          r.method = m.method;
          r.variant = m.variant;
          r.seed = seed;
          r.dir = fs::path("runs") / scene.name / fmt::format("{}v", views) / m.label() / fmt::format("seed{}", seed);
          const std::string where = fmt::format("run {} ({})", r.index, r.id());
          TrainConfig c;
          try {
            update_from_json(c, config.train);
            update_from_json(c, scene.train);
            if (!m.preset.empty()) {
              apply_d2gs_preset(c, m.preset);
              c.preset = m.preset;
            }
            const std::string scene_preset = !m.scene_preset.empty() ? m.scene_preset
                                             : m.use_scene_preset   ? scene.scene_preset
                                                                    : std::string();
            if (m.use_scene_preset && m.scene_preset.empty() && scene.scene_preset.empty())
              fail("method {} asks for the scene preset but scene {} names none", m.label(), scene.name);
            if (!scene_preset.empty()) {
              apply_scene_preset(c, scene_preset);
              c.scene_preset = scene_preset;
            }
            update_from_json(c, m.options);
            c.init = resolve_init_path(c.init, config.data_root);
            c.source = scene.source;
            c.model_dir = (root / r.dir).string();
            c.n_views = views;
            c.seed = seed;
            c.method = m.method;
            std::vector<int> checkpoints;
            for (int it = config.checkpoint_every; it < c.iterations; it += config.checkpoint_every)
              checkpoints.push_back(it);
            checkpoints.push_back(c.iterations);  // a run killed during its final evaluation resumes there
            c.checkpoint_iterations = checkpoints;
            c.validate();
          } catch (const Error& e) {
            fail_file(config.file, "{}: {}", where, e.what());
          }
          to_json(r.train_config, c);
          runs.push_back(std::move(r));
        }
  // Each run's log, config and lock are named by its id: two runs of one id would share them.
  std::map<std::string, int> ids;
  for (const auto& r : runs)
    if (const auto [it, fresh] = ids.emplace(r.id(), r.index); !fresh)
      fail_file(config.file, "runs {} and {} have one id ({}): rename a scene or a variant", it->second, r.index, r.id());
  return runs;
}

}  // namespace d2gs::experiment
