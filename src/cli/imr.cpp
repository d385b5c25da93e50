// d2gs imr: Inter-Model Robustness of independently trained models of one scene (method.md §7,
// docs/imr.md).
//   d2gs imr RUN_OR_PLY RUN_OR_PLY... [-s SCENE [-r R]] [--reference-camera K] [--epsilon 0.1]
//            [--samples 10000] [--tolerance 1e-4] [--max-iterations 10000] [--exact-bures] [--debiased]
//            [--cost stored|stored-double|on-the-fly] [--no-clamp] [--no-normalize] [--no-epsilon-scaling]
//            [--json OUT.json]
// A folder argument is a training run: its highest point_cloud/iteration_N/point_cloud.ply is used.
// Reference camera: camera K (default 0, the release's first test camera = global image 0) of the scene
// given with -s; without -s an identity camera at the origin is used (with a warning).
#include <algorithm>
#include <cmath>
#include <chrono>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "cli/commands.hpp"
#include "cli/scene_flags.hpp"
#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/json_value.hpp"
#include "d2gs/core/log.hpp"
#include "d2gs/eval/imr.hpp"
#include "d2gs/model/ply.hpp"
#include "d2gs/scene/scene.hpp"
#include "d2gs/train/config.hpp"

namespace d2gs::cli {
namespace {
namespace fs = std::filesystem;

// The smallest --epsilon on the mean-normalised cost (docs/imr.md).
constexpr double kMinNormalizedEpsilon = 1e-6;

struct ImrCommandOptions {
  std::vector<std::string> inputs;
  std::string source;
  int resolution = 1;
  int reference_camera = 0;
  // The library's defaults (ImrOptions), so help text and behaviour cannot drift from them.
  double epsilon = ImrOptions{}.sinkhorn.epsilon;
  std::size_t samples = ImrOptions{}.mixture.samples;
  std::size_t strata_phase = ImrOptions{}.mixture.phase;
  double tolerance = ImrOptions{}.sinkhorn.tolerance;
  double marginal_tolerance = ImrOptions{}.sinkhorn.marginal_tolerance;
  int max_iterations = ImrOptions{}.sinkhorn.max_iterations;
  bool exact_bures = false;
  bool debiased = false;
  bool no_clamp = false;
  bool no_normalize = false;
  bool epsilon_scaling = ImrOptions{}.sinkhorn.epsilon_scaling;
  int threads = 0;
  int anderson = ImrOptions{}.sinkhorn.anderson_depth;
  int anderson_max_restarts = ImrOptions{}.sinkhorn.anderson_max_restarts;
  double epsilon_factor = ImrOptions{}.sinkhorn.epsilon_factor;
  double stage_tolerance = ImrOptions{}.sinkhorn.stage_tolerance;
  bool plain_solver = false;
  bool accelerated = false;
  std::string cost = "stored";
  std::string solver = to_string(ImrOptions{}.sinkhorn.method);
  std::string json;
};

// The scene a run folder records, as the reference camera is taken from it when -s is not given.
struct RecordedScene {
  std::string source;  // the scene folder, resolved from the run folder (recorded_source)
  int resolution = 1;
};

// IMR compares models of one scene and split (docs/imr.md): run folders whose config.json records another
// scene folder, view count or split than the first run folder (or than -s) are refused, models of different
// methods get a warning. Bare PLY files record nothing and are not checked. Without -s, returns the scene and
// resolution of the first run folder (whose scene must then be a folder from here); none without run folders.
std::optional<RecordedScene> check_runs_share_a_scene(const std::vector<std::string>& inputs,
                                                      const std::string& source_flag) {
  struct Recorded {
    std::string input;
    nlohmann::json values;  // source (canonical), n_views, train_views, test_views
    std::string method;
  };
  std::vector<Recorded> runs;
  std::optional<RecordedScene> first;
  for (const auto& input : inputs) {
    const fs::path cfg = fs::path(input) / "config.json";
    if (!fs::is_regular_file(cfg)) continue;
    Recorded r{input, nlohmann::json::object(), ""};
    try {
      const auto j = read_json_file(cfg);
      if (!j.is_object() || !j.contains("source") || !j["source"].is_string()) fail("no 'source' string");
      const std::string source = recorded_source(input, j["source"].get<std::string>()).string();
      r.values["scene folder"] = absolute_path(source);
      for (const char* key : {"n_views", "train_views", "test_views"})
        r.values[key] = j.value(key, nlohmann::json());
      if (j.contains("method") && j["method"].is_string()) r.method = j["method"].get<std::string>();
      if (runs.empty() && source_flag.empty()) {
        if (!j.contains("resolution")) fail("no 'resolution'");
        RecordedScene scene{source, json_number<int>(j["resolution"], "resolution")};
        check_resolution(scene.resolution);
        if (!fs::is_directory(scene.source))
          fail("the recorded scene '{}' is not a folder from here (give it with -s)", scene.source);
        first = std::move(scene);
      }
    } catch (const nlohmann::json::exception& e) {
      fail_file(cfg, "cannot read the run's scene ({})", e.what());
    } catch (const Error& e) {
      fail_file(cfg, "cannot read the run's scene: {}", e.what());
    }
    if (!source_flag.empty() && r.values["scene folder"] != absolute_path(source_flag))
      fail_file(cfg, "the run was trained on {}, not on the scene -s {}: IMR compares models of one scene",
                r.values["scene folder"].get<std::string>(), source_flag);
    if (!runs.empty())
      for (const auto& [key, value] : runs.front().values.items())
        if (r.values[key] != value)
          fail_file(cfg, "the run's {} is {}, that of {} is {}: IMR compares models of one scene and split", key,
                    r.values[key].dump(), runs.front().input, value.dump());
    runs.push_back(std::move(r));
  }
  for (const auto& r : runs)
    if (r.method != runs.front().method) {
      spdlog::warn("imr: {} was trained with --method {}, {} with {}: IMR is defined over models of one method",
                   r.input, r.method, runs.front().input, runs.front().method);
      break;
    }
  return first;
}

// A PLY file, or a run folder's highest point_cloud/iteration_N/point_cloud.ply.
std::filesystem::path resolve_model(const std::filesystem::path& input) {
  if (fs::is_regular_file(input)) return input;
  std::error_code ec;
  if (fs::exists(input, ec) && !fs::is_directory(input, ec)) require_regular_file(input);  // a pipe or device: said so
  if (!fs::is_directory(input)) fail_file(input, "no such model file or run folder");
  const fs::path clouds = input / "point_cloud";
  long best = -1;
  fs::path found;
  if (fs::is_directory(clouds))
    for (const auto& entry : fs::directory_iterator(clouds)) {
      const std::string name = entry.path().filename().string();
      if (!entry.is_directory() || name.rfind("iteration_", 0) != 0) continue;
      const std::string digits = name.substr(10);
      if (digits.empty() || digits.size() > 12 || !std::all_of(digits.begin(), digits.end(), ::isdigit)) continue;
      const long n = std::stol(digits);
      if (n > best && fs::is_regular_file(entry.path() / "point_cloud.ply")) {
        best = n;
        found = entry.path() / "point_cloud.ply";
      }
    }
  if (best < 0) fail_file(input, "run folder without point_cloud/iteration_N/point_cloud.ply");
  return found;
}

nlohmann::json stages_json(const TransportResult& t) {
  nlohmann::json out = nlohmann::json::array();
  for (const SinkhornStage& s : t.stages)
    out.push_back({{"epsilon", s.epsilon}, {"iterations", s.iterations}, {"accelerated", s.accelerated}, {"restarts", s.restarts},
                   {"absorptions", s.absorptions}, {"row_refreshes", s.row_refreshes}, {"seconds", s.seconds}});
  return out;
}

nlohmann::json transport_json(const TransportResult& t) {
  return {{"transport_cost", t.transport_cost}, {"scale", t.scale}, {"max_position_term", t.max_position_term},
          {"normalized_transport_cost", t.normalized_cost}, {"iterations", t.iterations},
          {"marginal_error_l1", t.marginal_error}, {"last_potential_change", t.last_change},
          {"converged", t.converged}, {"seconds", t.seconds}, {"stages", stages_json(t)}};
}

int run_imr(const ImrCommandOptions& o) {
  // Every option first: a bad value fails before any model is loaded.
  CostStorage storage = CostStorage::StoredFloat;
  if (o.cost == "stored") storage = CostStorage::StoredFloat;
  else if (o.cost == "stored-double") storage = CostStorage::StoredDouble;
  else if (o.cost == "on-the-fly") storage = CostStorage::OnTheFly;
  else fail("option --cost must be stored, stored-double or on-the-fly (got '{}')", o.cost);
  SinkhornMethod method = SinkhornMethod::LogDomain;
  if (o.solver == "log-domain") method = SinkhornMethod::LogDomain;
  else if (o.solver == "kernel") method = SinkhornMethod::StabilizedKernel;
  else fail("option --solver must be kernel or log-domain (got '{}')", o.solver);
  if (o.inputs.size() < 2) fail("imr needs at least 2 models, got {}", o.inputs.size());
  if (!(o.epsilon > 0.0) || !std::isfinite(o.epsilon)) fail("option --epsilon must be positive (got {})", o.epsilon);
  // On the cost divided by its mean, a smaller ε is below what the float cost and kernel resolve: the solve would
  // stop in rounding on a plan that is no solution.
  if (!o.no_normalize && o.epsilon < kMinNormalizedEpsilon)
    fail("option --epsilon must be ≥ {:g} on the mean-normalised cost (got {:g})", kMinNormalizedEpsilon, o.epsilon);
  if (!(o.tolerance >= 0.0) || !std::isfinite(o.tolerance))
    fail("option --tolerance must be ≥ 0 (got {})", o.tolerance);
  if (!(o.marginal_tolerance >= 0.0) || !std::isfinite(o.marginal_tolerance))
    fail("option --marginal-tolerance must be ≥ 0 (got {})", o.marginal_tolerance);
  if (o.max_iterations < 1) fail("option --max-iterations must be ≥ 1 (got {})", o.max_iterations);
  if (o.reference_camera < 0) fail("option --reference-camera must be ≥ 0 (got {})", o.reference_camera);
  // OpenMP is asked for this many threads as given: beyond a few thousand it cannot make them (a crash).
  if (o.threads < 0 || o.threads > 1024) fail("option --threads must be in [0, 1024] (got {})", o.threads);
  if (o.anderson < 0 || o.anderson > 100) fail("option --anderson must be in [0, 100] (got {})", o.anderson);
  if (!(o.epsilon_factor > 0.0 && o.epsilon_factor < 1.0))
    fail("option --epsilon-factor must be in (0, 1) (got {})", o.epsilon_factor);
  if (!(o.stage_tolerance > 0.0) || !std::isfinite(o.stage_tolerance))
    fail("option --stage-tolerance must be positive (got {})", o.stage_tolerance);
  if (!o.source.empty()) check_resolution(o.resolution);
  if (!o.json.empty()) {
    check_output_file(o.json);
    // Only an earlier result of d2gs imr is replaced (an object with "imr" and "pairs"): not a model given
    // as input, a run's config.json or any other file named by mistake.
    std::error_code ec;
    if (fs::exists(o.json, ec)) {
      nlohmann::json earlier;
      try {
        earlier = read_json_file(o.json);
      } catch (const Error&) {
      }
      if (!earlier.is_object() || !earlier.contains("imr") || !earlier.contains("pairs"))
        fail_file(o.json, "exists and is not an earlier result of d2gs imr: --json replaces only those (choose another file)");
    }
  }
  ImrOptions options;
  options.mixture.samples = o.samples;
  options.mixture.phase = o.strata_phase;
  options.cost.shape = o.exact_bures ? ShapeCost::ExactBures : ShapeCost::TaylorBures;
  options.cost.clamp_shape = !o.no_clamp;
  options.cost.normalize = !o.no_normalize;
  options.sinkhorn.epsilon = o.epsilon;
  options.sinkhorn.tolerance = o.tolerance;
  options.sinkhorn.marginal_tolerance = o.marginal_tolerance;
  options.sinkhorn.max_iterations = o.max_iterations;
  options.sinkhorn.epsilon_scaling = o.epsilon_scaling;
  options.sinkhorn.threads = o.threads;
  options.sinkhorn.anderson_depth = o.anderson;
  options.sinkhorn.epsilon_factor = o.epsilon_factor;
  options.sinkhorn.stage_tolerance = o.stage_tolerance;
  options.sinkhorn.method = method;
  options.sinkhorn.anderson_max_restarts = o.anderson_max_restarts;
  if (o.plain_solver && o.accelerated) fail("options --plain-solver and --accelerated exclude each other");
  if (o.plain_solver) use_plain_solver(options.sinkhorn);  // plain iterations, ε halved, stages to 1e-2
  if (o.accelerated) use_accelerated_solver(options.sinkhorn);
  // A solve that takes long says where it stands every 10 s (iteration, change against the tolerance).
  {
    using Clock = std::chrono::steady_clock;
    auto last = std::make_shared<Clock::time_point>(Clock::now());
    auto started = std::make_shared<Clock::time_point>(Clock::now());
    const int max_iterations = o.max_iterations;
    options.sinkhorn.on_iteration = [last, started, max_iterations](int iteration, double change, double tolerance) {
      const auto now = Clock::now();
      if (iteration == 1) *started = now;
      if (now - *last < std::chrono::seconds(10)) return;
      *last = now;
      spdlog::info("imr: Sinkhorn iteration {}/{}: potential change {:.3g} (stops below {:.3g}), {:.0f} s", iteration,
                   max_iterations, change, tolerance, std::chrono::duration<double>(now - *started).count());
    };
  }
  options.debiased = o.debiased;
  options.storage = storage;

  Camera reference;
  std::string reference_name = "identity camera at the origin";
  std::string source = o.source;
  int resolution = o.resolution;
  // A training run folder records its scene: without -s, the reference camera is taken from there.
  if (const auto recorded = check_runs_share_a_scene(o.inputs, o.source)) {
    source = recorded->source;
    resolution = recorded->resolution;
  }
  if (!source.empty()) {
    SceneLoadOptions load;
    load.resolution = resolution;
    const Scene scene = load_scene(source, load);
    if (o.reference_camera < 0 || o.reference_camera >= static_cast<int>(scene.cameras.size()))
      fail("--reference-camera {} is outside the scene's {} cameras", o.reference_camera, scene.cameras.size());
    reference = scene.cameras[static_cast<std::size_t>(o.reference_camera)];
    reference_name = fmt::format("camera {} ({}) of {}", o.reference_camera, reference.image_name, source);
  } else {
    spdlog::warn("imr: no scene given (-s) and no run folder: depth strata use an identity camera at the origin, "
                 "not the release's first test camera");
  }

  std::vector<GaussianMixture> mixtures;
  nlohmann::json models = nlohmann::json::array();
  for (const auto& input : o.inputs) {
    const std::filesystem::path path = resolve_model(input);
    const Gaussians model = read_gaussians_ply(path);
    if (model.size() == 0) fail_file(path, "the model has no Gaussians (0 vertices); IMR compares distributions");
    try {
      mixtures.push_back(mixture_from_model(model, reference, options.mixture));
    } catch (const Error& e) {
      fail_file(path, "{}", e.what());
    }
    spdlog::info("imr: model {}: {} ({} Gaussians, {} components)", mixtures.size() - 1, path.string(), model.size(),
                 mixtures.back().size());
    models.push_back({{"input", input}, {"ply", path.string()}, {"gaussians", model.size()},
                      {"components", mixtures.back().size()}});
  }

  // Identical inputs (the same Gaussians) are said so: their S is the entropic bias alone, not a difference.
  const auto identical = [&mixtures](std::size_t a, std::size_t b) {
    return mixtures[a].weights == mixtures[b].weights && mixtures[a].means == mixtures[b].means &&
           mixtures[a].covariances == mixtures[b].covariances;
  };
  const ImrResult result = compute_imr(mixtures, options, [](const std::string& line) { spdlog::info("imr: {}", line); });

  std::printf("IMR of %zu models: cost %s%s%s, eps %g, samples %zu, tolerance %g, %s; reference: %s\n",
              mixtures.size(), to_string(options.cost.shape), options.cost.clamp_shape ? ", shape clamped" : "",
              options.cost.normalize ? ", mean-normalised" : "", o.epsilon, o.samples, o.tolerance,
              to_string(options.storage), reference_name.c_str());
  std::printf("%-6s %14s %12s %12s %6s %11s %5s%s\n", "pair", "S", "d", "scale", "iters", "marg.err", "conv",
              o.debiased ? "       debiased" : "");
  std::size_t unconverged = 0, same = 0;
  for (const auto& p : result.pairs) {
    const auto& t = p.transport;
    std::printf("%-6s %14.6g %12.6g %12.6g %6d %11.3g %5s", fmt::format("{}-{}", p.a, p.b).c_str(), t.transport_cost,
                p.distance, t.scale, t.iterations, t.marginal_error, t.converged ? "yes" : "NO");
    if (p.debiased) std::printf(" %14.6g", *p.debiased);
    if (identical(p.a, p.b)) std::printf("  (identical models)");
    std::printf("\n");
    same += identical(p.a, p.b) ? 1 : 0;
    if (!t.converged && t.iterations < o.max_iterations) {
      ++unconverged;
      spdlog::warn(
          "imr: pair {}-{} did not converge: its plan's marginal error {:.3g} is above {:g} (the stopping "
          "rule was met in rounding: choose a larger --epsilon); its S is meaningless",
          p.a, p.b, t.marginal_error, kMaxConvergedMarginalError);
    } else if (!t.converged) {
      ++unconverged;
      spdlog::warn("imr: pair {}-{} did not converge: stopped at --max-iterations {} with a potential change of {:.3g} "
                   "(tolerance {:.3g}) and a marginal error of {:.3g}; its S is approximate{}",
                   p.a, p.b, t.iterations, t.last_change, o.tolerance, t.marginal_error,
                   o.marginal_tolerance > 0.0 ? "" : " (--marginal-tolerance stops on the plan's marginals instead)");
    }
  }
  for (std::size_t k = 0; k < result.self.size(); ++k)
    std::printf("self %zu: S(%zu,%zu) = %.6g (%d iterations)\n", k, k, k, result.self[k].transport_cost,
                result.self[k].iterations);
  std::printf("IMR = %.6f%s\n", result.imr,
              unconverged ? fmt::format(" (APPROXIMATE: {} of {} transport problems did not converge)", unconverged,
                                        result.pairs.size()).c_str()
                          : "");
  if (result.imr_debiased) std::printf("IMR (debiased) = %.6f\n", *result.imr_debiased);
  else if (o.debiased) std::printf("IMR (debiased): undefined, every debiased divergence is 0\n");
  if (same > 0)
    std::printf("note: %s identical (the same Gaussians): S of identical models is the entropic bias S(A,A) of the "
                "regularised transport, not a difference between runs; --debiased removes it (docs/imr.md)\n",
                same == result.pairs.size() ? "all models are" : fmt::format("{} pair(s) of models are", same).c_str());

  if (!o.json.empty()) {
    nlohmann::json out;
    out["models"] = models;
    out["reference_camera"] = reference_name;
    out["options"] = {{"epsilon", o.epsilon}, {"samples", o.samples}, {"strata_phase", o.strata_phase},
                      {"tolerance", o.tolerance}, {"marginal_tolerance", o.marginal_tolerance},
                      {"max_iterations", o.max_iterations}, {"shape_cost", to_string(options.cost.shape)},
                      {"clamp_shape", options.cost.clamp_shape}, {"normalize", options.cost.normalize},
                      {"cost_storage", to_string(options.storage)}, {"epsilon_scaling", o.epsilon_scaling},
                      {"epsilon_factor", options.sinkhorn.epsilon_factor},
                      {"stage_tolerance", options.sinkhorn.stage_tolerance},
                      {"anderson_depth", options.sinkhorn.anderson_depth},
                      {"solver", to_string(options.sinkhorn.method)},
                      {"debiased", o.debiased}};
    nlohmann::json pairs = nlohmann::json::array();
    for (const auto& p : result.pairs) {
      nlohmann::json j = transport_json(p.transport);
      j["a"] = p.a;
      j["b"] = p.b;
      j["distance"] = p.distance;
      if (p.debiased) j["debiased_divergence"] = *p.debiased;
      j["identical_models"] = identical(p.a, p.b);
      pairs.push_back(j);
    }
    out["pairs"] = pairs;
    nlohmann::json self = nlohmann::json::array();
    for (const auto& t : result.self) self.push_back(transport_json(t));
    if (!result.self.empty()) out["self"] = self;
    out["imr"] = result.imr;
    out["converged"] = unconverged == 0;
    if (result.imr_debiased) out["imr_debiased"] = *result.imr_debiased;
    write_file_atomic(o.json, out.dump(2) + "\n");
  }
  return 0;
}

}  // namespace

Run add_imr_command(CLI::App& app) {
  auto o = std::make_shared<ImrCommandOptions>();
  CLI::App* sub = app.add_subcommand("imr", "Inter-Model Robustness of independently trained models (docs/imr.md)");
  add_option(*sub, "models", o->inputs, "PLY model files or training run folders (highest point_cloud/iteration_N)")
      ->required();
  add_option(*sub, "-s,--source", o->source, "Scene whose camera is the depth-strata reference (metadata only)");
  add_resolution_flag(*sub, o->resolution);
  add_option(*sub, "--reference-camera", o->reference_camera, "Camera index in the scene (0 = release: image 0)")
      ->capture_default_str();
  add_option(*sub, "--epsilon", o->epsilon, "Entropic regularisation (on the normalised cost)")->capture_default_str();
  add_option(*sub, "--samples", o->samples, "Depth-strata sample count n (0 = all Gaussians)")->capture_default_str();
  add_option(*sub, "--strata-phase", o->strata_phase,
             "Start each depth third's stride k ranks later (k mod its stride; 0 = the release's subsample): "
             "IMR of other subsamples, to see how much it depends on the one taken (docs/imr.md)")
      ->capture_default_str();
  add_option(*sub, "--tolerance", o->tolerance, "Stop when the log-potentials change less than this")
      ->capture_default_str();
  add_option(*sub, "--marginal-tolerance", o->marginal_tolerance,
             "Also stop when the plan's L1 marginal error is below this (0 = off): ends solves whose low-mass "
             "components' potentials drift while the plan no longer changes (docs/imr.md)")
      ->capture_default_str();
  add_option(*sub, "--max-iterations", o->max_iterations, "Sinkhorn iteration limit")->capture_default_str();
  sub->add_flag("--exact-bures", o->exact_bures, "Exact Bures shape term instead of the release's Taylor form");
  sub->add_flag("--debiased", o->debiased, "Also compute S(A,A), S(B,B) and the debiased divergence");
  add_option(*sub, "--cost", o->cost, "Cost matrix: stored (float), stored-double or on-the-fly")
      ->capture_default_str();
  sub->add_flag("--no-clamp", o->no_clamp, "Do not clamp the shape term to [0, max position term]");
  sub->add_flag("--no-normalize", o->no_normalize, "Do not divide the cost by its mean (epsilon in raw units)");
  sub->add_flag("--epsilon-scaling,!--no-epsilon-scaling", o->epsilon_scaling,
                "Anneal epsilon from the largest cost down (warm starts; default on): the same plan in "
                "far fewer iterations; --no-epsilon-scaling solves at epsilon from the start");
  add_option(*sub, "--anderson", o->anderson,
             "Anderson acceleration depth (0 = plain Sinkhorn); the solve still ends on plain iterations with "
             "the same stopping rule")
      ->capture_default_str();
  add_option(*sub, "--anderson-max-restarts", o->anderson_max_restarts,
             "Safeguard restarts after which an epsilon stage goes on with plain iterations (-1: no limit)")
      ->capture_default_str();
  add_option(*sub, "--epsilon-factor", o->epsilon_factor, "epsilon-scaling: ratio of successive epsilon stages")
      ->capture_default_str();
  add_option(*sub, "--stage-tolerance", o->stage_tolerance,
             "epsilon-scaling: potential change that ends an intermediate stage")
      ->capture_default_str();
  sub->add_flag("--plain-solver", o->plain_solver,
                "Plain Sinkhorn, epsilon halved per stage, intermediate stages to 1e-2 (the default before the "
                "stabilised kernel; overrides --anderson, --epsilon-factor, --stage-tolerance, --anderson-max-restarts)");
  sub->add_flag("--accelerated", o->accelerated,
                "Anderson acceleration (depth 10, no restart cap), epsilon /4 per stage, intermediate stages to 0.1: "
                "the same plan and stopping rule in fewer iterations (the default; docs/imr.md)");
  add_option(*sub, "--solver", o->solver,
             "Sinkhorn iterations: kernel (stabilised scaling form: a float kernel stored once per absorption, "
             "matrix-vector products per iteration) or log-domain (a log-sum-exp per entry per half-iteration); "
             "the same problem and stopping rule (docs/imr.md)")
      ->capture_default_str();
  add_option(*sub, "--threads", o->threads, "OpenMP threads (0 = automatic)")->capture_default_str();
  add_option(*sub, "--json", o->json, "Write every number to this JSON file");
  return [o]() -> int { return run_imr(*o); };
}

}  // namespace d2gs::cli
