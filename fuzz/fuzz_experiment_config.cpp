// libFuzzer target: a `d2gs experiment --config` file on arbitrary bytes, read and expanded into runs as
// the command does. Any input must either be taken or throw d2gs::Error; every expanded run carries a
// configuration that `d2gs train --config` takes back unchanged.
#include <cstdint>
#include <cstdlib>
#include <string_view>

#include <nlohmann/json.hpp>

#include "d2gs/core/error.hpp"
#include "d2gs/core/json_value.hpp"
#include "d2gs/experiment/experiment_config.hpp"
#include "d2gs/train/config.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  try {
    const nlohmann::json j = d2gs::parse_json(text, "fuzz.json");
    const auto c = d2gs::experiment::parse_experiment_config(j, "fuzz.json", "/data");
    if (c.scenes.empty() || c.views.empty() || c.seeds.empty() || c.methods.empty()) std::abort();
    for (const int v : c.views)
      if (v < 0) std::abort();
    // Expansion is a product of the lists: keep the fuzzer's inputs to experiments of sane size.
    if (c.scenes.size() * c.views.size() * c.seeds.size() * c.methods.size() > 256) return 0;
    const auto runs = d2gs::experiment::expand_runs(c, "/nonexistent/fuzz-experiment");
    if (runs.size() != c.scenes.size() * c.views.size() * c.seeds.size() * c.methods.size()) std::abort();
    for (const auto& r : runs) {
      d2gs::TrainConfig t;
      d2gs::update_from_json(t, r.train_config);
      nlohmann::json back;
      to_json(back, t);
      if (back != r.train_config) std::abort();
    }
  } catch (const d2gs::Error&) {
  }
  return 0;
}
