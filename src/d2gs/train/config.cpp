#include "d2gs/train/config.hpp"

#include <algorithm>
#include <filesystem>
#include <set>
#include <string>

#include <nlohmann/json.hpp>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/json_value.hpp"
#include "d2gs/train/methods/registry.hpp"
#include "d2gs/train/options.hpp"

namespace d2gs {

void TrainConfig::validate() const {
  if (source.empty()) fail("option --source (-s) is required");
  if (model_dir.empty()) fail("option --model-path (-m) is required");
  check_method_name(method);
  for (const TrainOption& o : train_options()) o.check(*this);
  if (!(dd_drop.rate_min <= dd_drop.rate_max))
    fail("options --dd-rate-min/--dd-rate-max must satisfy 0 ≤ min ≤ max ≤ 1 (got {}, {})", dd_drop.rate_min,
         dd_drop.rate_max);
  if (init != "dense" && init != "sparse" && init != "random" && init != "sfm-all-views") {
    std::error_code ec;
    if (init.empty() || !std::filesystem::exists(init, ec))
      fail("option --init '{}' is not one of dense, sparse, random, sfm-all-views, and no such PLY file exists", init);
    if (std::filesystem::is_directory(init, ec))
      fail("option --init '{}' is a folder; expected dense, sparse, random, sfm-all-views or a PLY file", init);
  }
  check_output_folder(model_dir);  // a -m under a file fails here, before any work
  for (int it : save_iterations)
    if (it < 1 || it > iterations) fail("save iteration {} is outside 1..{}", it, iterations);
  for (int it : checkpoint_iterations)
    if (it < 1 || it > iterations) fail("checkpoint iteration {} is outside 1..{}", it, iterations);
  for (int it : test_iterations)
    if (it < 1 || it > iterations) fail("test iteration {} is outside 1..{}", it, iterations);
  if (stop_at < 0 || stop_at > iterations)
    fail("option --stop-at {} is outside 0..{} (0: train to --iterations)", stop_at, iterations);
}

SceneLoadOptions scene_load_options(const TrainConfig& c) {
  SceneLoadOptions lo;
  lo.resolution = c.resolution;
  lo.background = c.white_background ? glm::vec3(1.0f) : glm::vec3(0.0f);
  lo.image_source = c.image_source;
  return lo;
}

SplitOptions split_options(const TrainConfig& c) {
  SplitOptions so;
  so.n_views = c.n_views;
  so.train_views = c.train_views;
  so.test_views = c.test_views;
  return so;
}

void take_recorded_run_config(TrainConfig& c, const nlohmann::json& recorded) {
  if (!recorded.is_object()) fail("is not a JSON object of a run's options");
  for (const char* key : {"method", "source"})
    if (!recorded.contains(key)) fail("key '{}' is missing: not the config.json of a d2gs train run", key);
  update_from_json(c, recorded, RecordedKeys::Ignore);
  const nlohmann::json current = with_current_names(recorded);  // former names counted as present
  for (const TrainOption& o : train_options())
    if (!o.absent_means.is_null() && !current.contains(o.name)) o.set(c, o.absent_means);
  // The ranges d2gs train checked when it wrote the file: a value outside them was edited in since.
  check_method_name(c.method);
  for (const TrainOption& o : train_options()) {
    try {
      o.check(c);
    } catch (const Error& e) {  // "option --n-views must be ≥ 1 (got -1)" → "key 'n_views' must be ≥ 1 (got -1)"
      const std::string what = e.what(), flag = "option " + o.flag();
      if (what.starts_with(flag)) fail("key '{}'{}", o.name, what.substr(flag.size()));
      fail("key '{}': {}", o.name, what);
    }
  }
}

std::string absolute_path(const std::string& p) {
  std::error_code ec;
  const std::filesystem::path a = std::filesystem::weakly_canonical(std::filesystem::absolute(p), ec);
  return ec ? std::filesystem::absolute(p).lexically_normal().string() : a.string();
}

std::filesystem::path recorded_source(const std::filesystem::path& model_dir, const std::string& source) {
  const std::filesystem::path p = source;
  if (p.empty() || p.is_absolute()) return p;
  std::error_code ec;
  if (std::filesystem::is_directory(model_dir / p, ec)) return (model_dir / p).lexically_normal();
  return p;
}

void to_json(nlohmann::json& j, const TrainConfig& c) {
  j = nlohmann::json::object();
  for (const TrainOption& o : train_options()) j[o.name] = o.get(c);
}

void update_from_json(TrainConfig& c, const nlohmann::json& j, RecordedKeys recorded) {
  if (!j.is_object()) fail("expected a JSON object of options, got {}", j.type_name());
  TrainConfig out = c;  // `c` changes only when every key is taken
  std::set<const TrainOption*> seen;
  for (const auto& [key, value] : j.items()) {
    if (recorded == RecordedKeys::Ignore &&
        std::find_if(std::begin(kRecordedKeys), std::end(kRecordedKeys), [&k = key](const char* r) { return k == r; }) !=
            std::end(kRecordedKeys))
      continue;
    const TrainOption* o = find_train_option(key);
    if (!o) fail("unknown key '{}'", key);
    if (!seen.insert(o).second) fail("key '{}' names option '{}' a second time (a former name of it is also given)", key, o->name);
    o->set(out, value);
  }
  c = std::move(out);
}

}  // namespace d2gs
