#include "d2gs/train/config.hpp"

#include <algorithm>
#include <set>

#include <nlohmann/json.hpp>

#include "d2gs/core/error.hpp"

namespace d2gs {

const char* to_string(Method m) {
  switch (m) {
    case Method::Gs3d: return "3dgs";
    case Method::DropGaussian: return "dropgaussian";
    case Method::D2gs: return "d2gs";
  }
  return "?";
}

Method method_from_string(const std::string& s) {
  if (s == "3dgs") return Method::Gs3d;
  if (s == "dropgaussian") return Method::DropGaussian;
  if (s == "d2gs") return Method::D2gs;
  fail("unknown method '{}' (expected 3dgs, dropgaussian or d2gs)", s);
}

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
  fail("config: {} '{}' is not one of {}", key, s, list);
}

}  // namespace

void TrainConfig::validate() const {
  const auto positive = [](double v, const char* name) {
    if (!(v > 0)) fail("option {} must be positive (got {})", name, v);
  };
  if (source.empty()) fail("option --source (-s) is required");
  if (model_dir.empty()) fail("option --model-path (-m) is required");
  if (resolution != 1 && resolution != 2 && resolution != 4 && resolution != 8)
    fail("option -r must be 1, 2, 4 or 8 (got {})", resolution);
  if (n_views < 0) fail("option --n-views must be ≥ 0 (got {})", n_views);
  positive(iterations, "--iterations");
  if (init_dense_method != "sgbm" && init_dense_method != "patchmatch")
    fail("option --init-dense-method must be 'sgbm' or 'patchmatch' (got '{}')", init_dense_method);
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
  positive(density_refresh_every, "--density-refresh-every");
  if (dafe_mask_rule == DafeMaskRule::Percentile && !(dafe_tau >= 0 && dafe_tau <= 100))
    fail("option --dafe-tau must be a percentage in [0, 100] for the percentile rule (got {})", dafe_tau);
  if (dafe_mask_rule == DafeMaskRule::Threshold && !(dafe_tau >= 0 && dafe_tau <= 1))
    fail("option --dafe-tau must be a fraction in [0, 1] for the threshold rule (got {})", dafe_tau);
  if (!(dafe_lambda >= 0)) fail("option --dafe-lambda must be ≥ 0");
  positive(random_points, "--random-points");
  positive(log_every, "--log-every");
  for (int it : save_iterations)
    if (it < 1 || it > iterations) fail("save iteration {} is outside 1..{}", it, iterations);
  for (int it : checkpoint_iterations)
    if (it < 1 || it > iterations) fail("checkpoint iteration {} is outside 1..{}", it, iterations);
  for (int it : test_iterations)
    if (it < 1 || it > iterations) fail("test iteration {} is outside 1..{}", it, iterations);
}

void to_json(nlohmann::json& j, const TrainConfig& c) {
  j = nlohmann::json{
      {"source", c.source}, {"model_dir", c.model_dir}, {"resolution", c.resolution}, {"n_views", c.n_views},
      {"train_views", c.train_views}, {"test_views", c.test_views}, {"white_background", c.white_background},
      {"method", to_string(c.method)}, {"iterations", c.iterations}, {"seed", c.seed}, {"init", c.init},
      {"init_dense_method", c.init_dense_method}, {"random_points", c.random_points},
      {"position_lr", c.lr.means}, {"position_lr_final", c.position_lr_final}, {"sh_dc_lr", c.lr.sh_dc},
      {"sh_rest_lr", c.lr.sh_rest}, {"opacity_lr", c.lr.opacity}, {"scaling_lr", c.lr.scales},
      {"rotation_lr", c.lr.quats}, {"lambda_dssim", c.lambda_dssim}, {"sh_degree", c.sh_degree},
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
      {"density_refresh_every", c.density_refresh_every}, {"release_density_cache", c.release_density_cache},
      {"dafe", c.dafe}, {"dafe_prior_dir", c.dafe_prior_dir}, {"dafe_prior_kind", to_string(c.dafe_prior_kind)},
      {"dafe_mask_rule", to_string(c.dafe_mask_rule)}, {"dafe_tau", c.dafe_tau},
      {"dafe_loss_form", to_string(c.dafe_loss_form)}, {"dafe_lambda", c.dafe_lambda},
      {"save_iterations", c.save_iterations}, {"checkpoint_iterations", c.checkpoint_iterations},
      {"test_iterations", c.test_iterations}, {"log_every", c.log_every}, {"quiet", c.quiet}};
}

void update_from_json(TrainConfig& c, const nlohmann::json& j) {
  if (!j.is_object()) fail("config: expected a JSON object");
  // Round-trip through to_json to know every key and its type.
  nlohmann::json known;
  to_json(known, c);
  for (const auto& [key, value] : j.items()) {
    if (!known.contains(key)) fail("config: unknown key '{}'", key);
    const auto& ref = known[key];
    const bool ok = (ref.is_number() && value.is_number()) || (ref.is_boolean() && value.is_boolean()) ||
                    (ref.is_string() && value.is_string()) || (ref.is_array() && value.is_array());
    if (!ok) fail("config: key '{}' has the wrong type (expected {})", key, ref.type_name());
    known[key] = value;
  }
  try {
    const auto& k = known;
    c.source = k["source"];
    c.model_dir = k["model_dir"];
    c.resolution = k["resolution"];
    c.n_views = k["n_views"];
    c.train_views = k["train_views"].get<std::vector<int>>();
    c.test_views = k["test_views"].get<std::vector<int>>();
    c.white_background = k["white_background"];
    c.method = method_from_string(k["method"]);
    c.iterations = k["iterations"];
    c.seed = k["seed"];
    c.init = k["init"];
    c.init_dense_method = k["init_dense_method"];
    c.random_points = k["random_points"];
    c.lr.means = k["position_lr"];
    c.position_lr_final = k["position_lr_final"];
    c.lr.sh_dc = k["sh_dc_lr"];
    c.lr.sh_rest = k["sh_rest_lr"];
    c.lr.opacity = k["opacity_lr"];
    c.lr.scales = k["scaling_lr"];
    c.lr.quats = k["rotation_lr"];
    c.lambda_dssim = k["lambda_dssim"];
    c.sh_degree = k["sh_degree"];
    c.sh_increase_every = k["sh_increase_every"];
    c.densify.grad_threshold = k["densify_grad_threshold"];
    c.densify.percent_dense = k["percent_dense"];
    c.densify.min_opacity = k["min_opacity"];
    c.densify_from = k["densify_from"];
    c.densify_until = k["densify_until"];
    c.densify_every = k["densify_every"];
    c.opacity_reset_at = k["opacity_reset_at"].get<std::vector<int>>();
    c.dropgaussian_max_rate = k["dropgaussian_max_rate"];
    c.preset = k["preset"];
    c.scene_preset = k["scene_preset"];
    c.dd_drop.weight_depth = k["dd_weight_depth"];
    c.dd_drop.weight_density = k["dd_weight_density"];
    c.dd_drop.rate_min = k["dd_rate_min"];
    c.dd_drop.rate_max = k["dd_rate_max"];
    c.dd_drop.rate_iterations = k["dd_rate_iterations"];
    c.dd_drop.use_depth_score = k["dd_use_depth_score"];
    c.dd_drop.use_density_score = k["dd_use_density_score"];
    c.dd_drop.use_layers = k["dd_use_layers"];
    c.dd_drop.compensate = k["dd_compensate"];
    c.dd_drop.lambda_near = k["dd_lambda_near"];
    c.dd_drop.lambda_middle = k["dd_lambda_middle"];
    c.dd_drop.lambda_far = k["dd_lambda_far"];
    c.dd_drop.depth_mode = enum_from<DepthMode>(k["dd_depth_mode"], {{"euclidean", DepthMode::Euclidean}, {"release-dot", DepthMode::ReleaseDot}}, "dd_depth_mode");
    c.density_refresh_every = k["density_refresh_every"];
    c.release_density_cache = k["release_density_cache"];
    c.dafe = k["dafe"];
    c.dafe_prior_dir = k["dafe_prior_dir"];
    c.dafe_prior_kind = enum_from<PriorKind>(k["dafe_prior_kind"], {{"depth", PriorKind::Depth}, {"disparity", PriorKind::Disparity}}, "dafe_prior_kind");
    c.dafe_mask_rule = enum_from<DafeMaskRule>(k["dafe_mask_rule"], {{"percentile", DafeMaskRule::Percentile}, {"threshold", DafeMaskRule::Threshold}}, "dafe_mask_rule");
    c.dafe_tau = k["dafe_tau"];
    c.dafe_loss_form = enum_from<DafeLossForm>(k["dafe_loss_form"], {{"paper", DafeLossForm::Paper}, {"release", DafeLossForm::Release}}, "dafe_loss_form");
    c.dafe_lambda = k["dafe_lambda"];
    c.save_iterations = k["save_iterations"].get<std::vector<int>>();
    c.checkpoint_iterations = k["checkpoint_iterations"].get<std::vector<int>>();
    c.test_iterations = k["test_iterations"].get<std::vector<int>>();
    c.log_every = k["log_every"];
    c.quiet = k["quiet"];
  } catch (const nlohmann::json::exception& e) {
    fail("config: {}", e.what());
  }
}

}  // namespace d2gs
