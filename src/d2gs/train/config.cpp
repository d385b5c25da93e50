#include "d2gs/train/config.hpp"

#include <algorithm>
#include <filesystem>
#include <set>
#include <string>
#include <type_traits>

#include <nlohmann/json.hpp>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/json_value.hpp"
#include "d2gs/train/methods/registry.hpp"

namespace d2gs {

namespace {

const char* to_string(PriorKind k) { return k == PriorKind::Depth ? "depth" : "disparity"; }
const char* to_string(DafeMaskRule r) { return r == DafeMaskRule::Percentile ? "percentile" : "threshold"; }
const char* to_string(DafeLossForm f) { return f == DafeLossForm::Paper ? "paper" : "release"; }
const char* to_string(DepthMode m) { return m == DepthMode::Euclidean ? "euclidean" : "release-dot"; }

template <typename E>
E enum_from(const std::string& s, std::initializer_list<std::pair<const char*, E>> names, const char* key) {
  for (const auto& [name, value] : names)
    if (s == name) return value;
  std::string list;
  for (const auto& [name, value] : names) list += std::string(list.empty() ? "" : ", ") + name;
  fail("key '{}': '{}' is not one of {}", key, s, list);
}

// One key of a config into its field, type- and range-checked: integers must be JSON integers that fit
// the field (never truncated or wrapped), floating values finite and within the field's type. The
// options' own ranges are TrainConfig::validate()'s, shared with the command line.
template <typename T>
void read(const nlohmann::json& k, const char* key, T& field) {
  const nlohmann::json& v = k.at(key);
  if constexpr (std::is_same_v<T, bool> || std::is_same_v<T, std::string>) field = v.get<T>();
  else if constexpr (std::is_arithmetic_v<T>) field = json_number<T>(v, key);
  else field = json_number_list<typename T::value_type>(v, key);
}

}  // namespace

void TrainConfig::validate() const {
  const auto positive = [](double v, const char* name) {
    if (!(v > 0)) fail("option {} must be positive (got {})", name, v);
  };
  if (source.empty()) fail("option --source (-s) is required");
  if (model_dir.empty()) fail("option --model-path (-m) is required");
  check_method_name(method);
  if (resolution != 1 && resolution != 2 && resolution != 4 && resolution != 8)
    fail("option -r must be 1, 2, 4 or 8 (got {})", resolution);
  if (n_views < 0) fail("option --n-views must be ≥ 0 (got {})", n_views);
  positive(iterations, "--iterations");
  positive(lr.means, "--position-lr");
  positive(position_lr_final, "--position-lr-final");
  positive(lr.sh_dc, "--sh-dc-lr");
  positive(lr.sh_rest, "--sh-rest-lr");
  positive(lr.opacity, "--opacity-lr");
  positive(lr.scales, "--scaling-lr");
  positive(lr.quats, "--rotation-lr");
  if (!(lambda_dssim >= 0 && lambda_dssim <= 1)) fail("option --lambda-dssim must be in [0, 1]");
  if (sh_degree < 0 || sh_degree > 3) fail("option --sh-degree must be 0..3 (got {})", sh_degree);
  positive(sh_increase_every, "--sh-increase-every");
  positive(densify_every, "--densify-every");
  positive(densify.grad_threshold, "--densify-grad-threshold");
  if (!(densify.min_opacity >= 0 && densify.min_opacity < 1)) fail("option --min-opacity must be in [0, 1)");
  if (!(dropgaussian_max_rate >= 0 && dropgaussian_max_rate < 1)) fail("option --drop-rate must be in [0, 1)");
  const auto& d = dd_drop;
  if (!(d.rate_min >= 0 && d.rate_max <= 1 && d.rate_min <= d.rate_max))
    fail("options --dd-rate-min/--dd-rate-max must satisfy 0 ≤ min ≤ max ≤ 1 (got {}, {})", d.rate_min, d.rate_max);
  if (!(d.weight_depth >= 0 && d.weight_density >= 0)) fail("DD-Drop weights must be ≥ 0");
  positive(d.density_refresh_every, "--density-refresh-every");
  if (dafe.mask_rule == DafeMaskRule::Percentile && !(dafe.tau >= 0 && dafe.tau <= 100))
    fail("option --dafe-tau must be a percentage in [0, 100] for the percentile rule (got {})", dafe.tau);
  if (dafe.mask_rule == DafeMaskRule::Threshold && !(dafe.tau >= 0 && dafe.tau <= 1))
    fail("option --dafe-tau must be a fraction in [0, 1] for the threshold rule (got {})", dafe.tau);
  if (!(dafe.lambda >= 0)) fail("option --dafe-lambda must be ≥ 0");
  positive(random_points, "--random-points");
  if (init != "dense" && init != "sparse" && init != "random" && init != "sfm-all-views") {
    std::error_code ec;
    if (init.empty() || !std::filesystem::exists(init, ec))
      fail("option --init '{}' is not one of dense, sparse, random, sfm-all-views, and no such PLY file exists", init);
    if (std::filesystem::is_directory(init, ec))
      fail("option --init '{}' is a folder; expected dense, sparse, random, sfm-all-views or a PLY file", init);
  }
  check_output_folder(model_dir);  // a -m under a file fails here, before any work
  positive(log_every, "--log-every");
  for (int it : save_iterations)
    if (it < 1 || it > iterations) fail("save iteration {} is outside 1..{}", it, iterations);
  for (int it : checkpoint_iterations)
    if (it < 1 || it > iterations) fail("checkpoint iteration {} is outside 1..{}", it, iterations);
  for (int it : test_iterations)
    if (it < 1 || it > iterations) fail("test iteration {} is outside 1..{}", it, iterations);
}

SceneLoadOptions scene_load_options(const TrainConfig& c) {
  SceneLoadOptions lo;
  lo.resolution = c.resolution;
  lo.background = c.white_background ? glm::vec3(1.0f) : glm::vec3(0.0f);
  lo.image_source = c.image_source;
  return lo;
}

std::filesystem::path recorded_source(const std::filesystem::path& model_dir, const std::string& source) {
  const std::filesystem::path p = source;
  if (p.empty() || p.is_absolute()) return p;
  std::error_code ec;
  if (std::filesystem::is_directory(model_dir / p, ec)) return (model_dir / p).lexically_normal();
  return p;
}

void to_json(nlohmann::json& j, const TrainConfig& c) {
  j = nlohmann::json{
      {"source", c.source}, {"model_dir", c.model_dir}, {"resolution", c.resolution}, {"n_views", c.n_views},
      {"train_views", c.train_views}, {"test_views", c.test_views}, {"white_background", c.white_background},
      {"image_source", to_string(c.image_source)}, {"method", c.method}, {"iterations", c.iterations}, {"seed", c.seed}, {"init", c.init},
      {"random_points", c.random_points},
      {"position_lr", c.lr.means}, {"position_lr_final", c.position_lr_final}, {"sh_dc_lr", c.lr.sh_dc},
      {"sh_rest_lr", c.lr.sh_rest}, {"opacity_lr", c.lr.opacity}, {"scaling_lr", c.lr.scales},
      {"rotation_lr", c.lr.quats}, {"lambda_dssim", c.lambda_dssim},
      {"alpha_clamp_grad", c.alpha_clamp_pass_through ? "pass-through" : "exact"}, {"sh_degree", c.sh_degree},
      {"sh_increase_every", c.sh_increase_every},
      {"densify_grad_threshold", c.densify.grad_threshold}, {"percent_dense", c.densify.percent_dense},
      {"min_opacity", c.densify.min_opacity}, {"densify_from", c.densify_from}, {"densify_until", c.densify_until},
      {"densify_every", c.densify_every}, {"opacity_reset_at", c.opacity_reset_at},
      {"dropgaussian_max_rate", c.dropgaussian_max_rate}, {"preset", c.preset}, {"scene_preset", c.scene_preset},
      {"dd_weight_depth", c.dd_drop.weight_depth}, {"dd_weight_density", c.dd_drop.weight_density},
      {"dd_rate_min", c.dd_drop.rate_min}, {"dd_rate_max", c.dd_drop.rate_max},
      {"dd_rate_iterations", c.dd_drop.rate_iterations}, {"dd_use_depth_score", c.dd_drop.use_depth_score},
      {"dd_use_density_score", c.dd_drop.use_density_score}, {"dd_use_layers", c.dd_drop.use_layers},
      {"dd_compensate", c.dd_drop.compensate},
      {"dd_lambda_near", c.dd_drop.lambda_near}, {"dd_lambda_middle", c.dd_drop.lambda_middle},
      {"dd_lambda_far", c.dd_drop.lambda_far}, {"dd_depth_mode", to_string(c.dd_drop.depth_mode)},
      {"density_refresh_every", c.dd_drop.density_refresh_every},
      {"release_density_cache", c.dd_drop.release_density_cache}, {"dafe", c.dafe.enabled},
      {"dafe_prior_dir", c.dafe.prior}, {"dafe_prior_kind", to_string(c.dafe.prior_kind)},
      {"dafe_mask_rule", to_string(c.dafe.mask_rule)}, {"dafe_tau", c.dafe.tau},
      {"dafe_loss_form", to_string(c.dafe.loss_form)}, {"dafe_lambda", c.dafe.lambda},
      {"save_iterations", c.save_iterations}, {"checkpoint_iterations", c.checkpoint_iterations},
      {"test_iterations", c.test_iterations}, {"log_every", c.log_every}, {"quiet", c.quiet}};
}

void update_from_json(TrainConfig& c, const nlohmann::json& j) {
  if (!j.is_object()) fail("expected a JSON object of options, got {}", j.type_name());
  // Round-trip through to_json to know every key and its type.
  nlohmann::json known;
  to_json(known, c);
  for (const auto& [key, value] : j.items()) {
    if (!known.contains(key)) fail("unknown key '{}'", key);
    const auto& ref = known[key];
    const bool ok = (ref.is_number() && value.is_number()) || (ref.is_boolean() && value.is_boolean()) ||
                    (ref.is_string() && value.is_string()) || (ref.is_array() && value.is_array());
    if (!ok) fail("key '{}' has the wrong type (expected {}, got {})", key, ref.type_name(), value.type_name());
    known[key] = value;
  }
  try {
    const auto& k = known;
    read(k, "source", c.source);
    read(k, "model_dir", c.model_dir);
    read(k, "resolution", c.resolution);
    read(k, "n_views", c.n_views);
    read(k, "train_views", c.train_views);
    read(k, "test_views", c.test_views);
    read(k, "white_background", c.white_background);
    c.image_source = enum_from<ImageSource>(k["image_source"], {{"folder", ImageSource::Folder}, {"largest", ImageSource::Largest}}, "image_source");
    read(k, "method", c.method);
    check_method_name(c.method);
    read(k, "iterations", c.iterations);
    read(k, "seed", c.seed);
    read(k, "init", c.init);
    read(k, "random_points", c.random_points);
    read(k, "position_lr", c.lr.means);
    read(k, "position_lr_final", c.position_lr_final);
    read(k, "sh_dc_lr", c.lr.sh_dc);
    read(k, "sh_rest_lr", c.lr.sh_rest);
    read(k, "opacity_lr", c.lr.opacity);
    read(k, "scaling_lr", c.lr.scales);
    read(k, "rotation_lr", c.lr.quats);
    read(k, "lambda_dssim", c.lambda_dssim);
    c.alpha_clamp_pass_through = enum_from<bool>(k["alpha_clamp_grad"], {{"exact", false}, {"pass-through", true}}, "alpha_clamp_grad");
    read(k, "sh_degree", c.sh_degree);
    read(k, "sh_increase_every", c.sh_increase_every);
    read(k, "densify_grad_threshold", c.densify.grad_threshold);
    read(k, "percent_dense", c.densify.percent_dense);
    read(k, "min_opacity", c.densify.min_opacity);
    read(k, "densify_from", c.densify_from);
    read(k, "densify_until", c.densify_until);
    read(k, "densify_every", c.densify_every);
    read(k, "opacity_reset_at", c.opacity_reset_at);
    read(k, "dropgaussian_max_rate", c.dropgaussian_max_rate);
    read(k, "preset", c.preset);
    read(k, "scene_preset", c.scene_preset);
    read(k, "dd_weight_depth", c.dd_drop.weight_depth);
    read(k, "dd_weight_density", c.dd_drop.weight_density);
    read(k, "dd_rate_min", c.dd_drop.rate_min);
    read(k, "dd_rate_max", c.dd_drop.rate_max);
    read(k, "dd_rate_iterations", c.dd_drop.rate_iterations);
    read(k, "dd_use_depth_score", c.dd_drop.use_depth_score);
    read(k, "dd_use_density_score", c.dd_drop.use_density_score);
    read(k, "dd_use_layers", c.dd_drop.use_layers);
    read(k, "dd_compensate", c.dd_drop.compensate);
    read(k, "dd_lambda_near", c.dd_drop.lambda_near);
    read(k, "dd_lambda_middle", c.dd_drop.lambda_middle);
    read(k, "dd_lambda_far", c.dd_drop.lambda_far);
    c.dd_drop.depth_mode = enum_from<DepthMode>(k["dd_depth_mode"], {{"euclidean", DepthMode::Euclidean}, {"release-dot", DepthMode::ReleaseDot}}, "dd_depth_mode");
    read(k, "density_refresh_every", c.dd_drop.density_refresh_every);
    read(k, "release_density_cache", c.dd_drop.release_density_cache);
    read(k, "dafe", c.dafe.enabled);
    read(k, "dafe_prior_dir", c.dafe.prior);
    c.dafe.prior_kind = enum_from<PriorKind>(k["dafe_prior_kind"], {{"depth", PriorKind::Depth}, {"disparity", PriorKind::Disparity}}, "dafe_prior_kind");
    c.dafe.mask_rule = enum_from<DafeMaskRule>(k["dafe_mask_rule"], {{"percentile", DafeMaskRule::Percentile}, {"threshold", DafeMaskRule::Threshold}}, "dafe_mask_rule");
    read(k, "dafe_tau", c.dafe.tau);
    c.dafe.loss_form = enum_from<DafeLossForm>(k["dafe_loss_form"], {{"paper", DafeLossForm::Paper}, {"release", DafeLossForm::Release}}, "dafe_loss_form");
    read(k, "dafe_lambda", c.dafe.lambda);
    read(k, "save_iterations", c.save_iterations);
    read(k, "checkpoint_iterations", c.checkpoint_iterations);
    read(k, "test_iterations", c.test_iterations);
    read(k, "log_every", c.log_every);
    read(k, "quiet", c.quiet);
  } catch (const nlohmann::json::exception& e) {
    fail("{}", e.what());
  }
}

}  // namespace d2gs
