// libFuzzer target: a `d2gs train --config` file on arbitrary bytes, as the command reads it (parse,
// update_from_json, validate). Any input must either be taken or throw d2gs::Error; a configuration
// that is taken must survive to_json/update_from_json unchanged, and its integers be the file's, never
// wrapped or truncated.
#include <cstdint>
#include <cstdlib>
#include <initializer_list>
#include <utility>
#include <string_view>

#include <nlohmann/json.hpp>

#include "d2gs/core/error.hpp"
#include "d2gs/core/json_value.hpp"
#include "d2gs/train/config.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  try {
    nlohmann::json j = d2gs::parse_json(text, "fuzz.json");
    if (j.is_object())
      for (const char* recorded : {"init_is_oracle", "scene_extent", "split"}) j.erase(recorded);
    d2gs::TrainConfig c;
    d2gs::update_from_json(c, j);
    // Integers given are taken exactly (nlohmann compares 5.0 == 5, so a truncated 5.7 would show).
    for (const auto& [key, value] : std::initializer_list<std::pair<const char*, nlohmann::json>>{
             {"iterations", c.iterations}, {"resolution", c.resolution}, {"n_views", c.n_views}, {"seed", c.seed},
             {"sh_degree", c.sh_degree}, {"densify_every", c.densify_every}, {"random_points", c.random_points}})
      if (j.contains(key) && j[key] != value) std::abort();
    nlohmann::json once;
    to_json(once, c);
    d2gs::TrainConfig d;
    d2gs::update_from_json(d, once);
    nlohmann::json twice;
    to_json(twice, d);
    if (once != twice) std::abort();
    c.validate();
  } catch (const d2gs::Error&) {
  }
  return 0;
}
