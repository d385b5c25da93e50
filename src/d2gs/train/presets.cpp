#include "d2gs/train/presets.hpp"

#include <algorithm>

#include <fmt/ranges.h>
#include <nlohmann/json.hpp>

#include "d2gs/core/error.hpp"

namespace d2gs {

const std::vector<std::string>& d2gs_preset_names() {
  static const std::vector<std::string> names = {"paper", "release", "plus"};
  return names;
}

const std::vector<D2gsScenePreset>& d2gs_scene_presets() {
  // (w_d, w_ρ, r_min, r_max, mask %, λ_DAFE) per scene, method.md §4.
  static const std::vector<D2gsScenePreset> presets = {
      {"llff", "fern", .7, .3, .1, .3, 10, 1.0},       {"llff", "flower", .7, .3, .1, .3, 5, 1.5},
      {"llff", "fortress", .5, .5, .05, .3, 15, 1.0},  {"llff", "horns", .7, .3, .1, .3, 5, 1.0},
      {"llff", "leaves", .7, .3, .1, .5, 10, .25},     {"llff", "orchids", .5, .5, .05, .3, 10, .5},
      {"llff", "room", .15, .85, .05, .5, 20, .5},     {"llff", "trex", .15, .85, .05, .5, 5, .5},
      {"mipnerf360", "bicycle", .15, .85, .05, .5, 20, 1.0}, {"mipnerf360", "bonsai", .7, .3, .1, .3, 5, .5},
      {"mipnerf360", "counter", .15, .85, .05, .5, 5, .5},   {"mipnerf360", "garden", .3, .7, .05, .7, 15, .5},
      {"mipnerf360", "kitchen", .1, .9, .05, .5, 10, .5},    {"mipnerf360", "room", .3, .7, .05, .7, 5, .5},
      {"mipnerf360", "stump", .3, .7, .05, .7, 10, 1.0},
  };
  return presets;
}

void apply_d2gs_preset(TrainConfig& c, const std::string& preset) {
  if (preset == "paper") {
    c.dd_drop.depth_mode = DepthMode::Euclidean;
    c.dd_drop.release_density_cache = false;
    c.dd_drop.weight_depth = 0.5;
    c.dd_drop.weight_density = 0.5;
    c.dd_drop.rate_min = 0.05;
    c.dd_drop.rate_max = 0.3;
    c.dafe.mask_rule = DafeMaskRule::Percentile;
    c.dafe.tau = 5.0;
    c.dafe.loss_form = DafeLossForm::Paper;
    c.dafe.lambda = 1.0f;
  } else if (preset == "release") {
    // The release's values are TrainConfig's defaults (config.hpp): restore them.
    const TrainConfig d;
    c.dd_drop.depth_mode = d.dd_drop.depth_mode;
    c.dd_drop.release_density_cache = d.dd_drop.release_density_cache;
    c.dd_drop.weight_depth = d.dd_drop.weight_depth;
    c.dd_drop.weight_density = d.dd_drop.weight_density;
    c.dd_drop.rate_min = d.dd_drop.rate_min;
    c.dd_drop.rate_max = d.dd_drop.rate_max;
    c.dafe.mask_rule = d.dafe.mask_rule;
    c.dafe.tau = d.dafe.tau;
    c.dafe.loss_form = d.dafe.loss_form;
    c.dafe.lambda = d.dafe.lambda;
  } else if (preset == "plus") {
    // The release, with the two weight-free levers that won issue 25's screen together: each kept
    // Gaussian's opacity divided by (1 − p_i), and opacity decay in place of the opacity reset.
    apply_d2gs_preset(c, "release");
    c.dd_drop.compensate = true;
    if (std::find(c.regularisers.begin(), c.regularisers.end(), "opacity-decay") == c.regularisers.end())
      c.regularisers.push_back("opacity-decay");
    c.opacity_reset_at.clear();
  } else {
    fail("unknown D2GS preset '{}' (expected one of: {})", preset, fmt::join(d2gs_preset_names(), ", "));
  }
}

void apply_scene_preset(TrainConfig& c, const std::string& name) {
  const auto slash = name.find('/');
  const std::string dataset = slash == std::string::npos ? "" : name.substr(0, slash);
  const std::string scene = slash == std::string::npos ? name : name.substr(slash + 1);
  const D2gsScenePreset* found = nullptr;
  int matches = 0;
  std::string known;
  for (const auto& p : d2gs_scene_presets()) {
    known += fmt::format("{}{}/{}", known.empty() ? "" : ", ", p.dataset, p.scene);
    if (scene == p.scene && (dataset.empty() || dataset == p.dataset)) {
      found = &p;
      ++matches;
    }
  }
  if (matches == 0) fail("unknown scene preset '{}' (known: {})", name, known);
  if (matches > 1) fail("scene preset '{}' is ambiguous: name the dataset, e.g. llff/{} or mipnerf360/{}", name, scene, scene);
  c.dd_drop.weight_depth = found->weight_depth;
  c.dd_drop.weight_density = found->weight_density;
  c.dd_drop.rate_min = found->rate_min;
  c.dd_drop.rate_max = found->rate_max;
  c.dafe.mask_rule = DafeMaskRule::Percentile;
  c.dafe.tau = found->mask_percent;
  c.dafe.lambda = static_cast<float>(found->dafe_lambda);
}

void apply_given_options(TrainConfig& c, const nlohmann::json& given) {
  TrainConfig out = c;
  const auto named = [&given](const char* key) {
    return given.contains(key) && given[key].is_string() ? given[key].get<std::string>() : std::string();
  };
  if (const std::string preset = named("preset"); !preset.empty()) apply_d2gs_preset(out, preset);
  if (const std::string scene = named("scene_preset"); !scene.empty()) apply_scene_preset(out, scene);
  update_from_json(out, given);
  if (const std::string preset = named("preset"); !preset.empty() && out.method != "d2gs")
    fail("--preset {} is a D2GS preset, but the method is {} (give that method's options by name instead)", preset,
         out.method);
  c = std::move(out);
}

}  // namespace d2gs
