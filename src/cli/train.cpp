// d2gs train: sparse-view 3DGS / DropGaussian / D²GS training.
#include <fstream>

#include <nlohmann/json.hpp>

#include "cli/commands.hpp"
#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/json_value.hpp"
#include "d2gs/report/run_report.hpp"
#include "d2gs/train/methods/registry.hpp"
#include "d2gs/train/presets.hpp"
#include "d2gs/train/trainer.hpp"

namespace d2gs::cli {

Run add_train_command(CLI::App& app) {
  auto* cmd = app.add_subcommand("train", "Train a Gaussian model from the training views of a scene");
  cmd->footer(
      "Outputs (the original 3DGS layout): MODEL/config.json, cameras.json, input.ply,\n"
      "point_cloud/iteration_N/point_cloud.ply, train_log.jsonl, chkpntN.bin, test/ours_N/{renders,gt},\n"
      "results.json. Defaults are the hyper-parameters of method.md §2. One `d2gs train` at a time per\n"
      "MODEL folder (a lock); a run stopped before its first checkpoint starts again with the same command.\n"
      "Example: d2gs train -s ../shared/data/nerf_llff_data/fern -m out/fern_3dgs -r 8 --n-views 3 --method 3dgs");
  auto cfg = std::make_shared<TrainConfig>();
  auto config_file = std::make_shared<std::string>();
  auto resume = std::make_shared<std::string>();
  auto method = std::make_shared<std::string>("3dgs");
  // Every option maps to its key in config.json, so that flags given on the command line override a
  // --config file key by key.
  auto keys = std::make_shared<std::vector<std::pair<CLI::Option*, std::string>>>();
  const auto opt = [&](const char* flags, auto& member, const char* key, const char* help) {
    CLI::Option* o = cmd->add_option(flags, member, help);
    keys->emplace_back(o, key);
    return o;
  };
  const auto flag = [&](const char* flags, bool& member, const char* key, const char* help) {
    keys->emplace_back(cmd->add_flag(flags, member, help), key);
  };
  TrainConfig& d = *cfg;
  cmd->add_option("--config", *config_file, "JSON file of options (keys as in a saved config.json); flags override it");
  opt("-s,--source", d.source, "source", "Scene folder (COLMAP, LLFF or Blender)");
  opt("-m,--model-path", d.model_dir, "model_dir", "Output folder of the run");
  opt("-r,--resolution", d.resolution, "resolution", "1/R of full resolution: 1, 2, 4 or 8");
  opt("--n-views", d.n_views, "n_views", "Training views of the sparse-view split (0 = all non-test views)");
  opt("--train-views", d.train_views, "train_views", "Explicit training views (global indices)")->delimiter(',');
  opt("--test-views", d.test_views, "test_views", "Explicit test views (global indices)")->delimiter(',');
  flag("--white-background", d.white_background, "white_background", "White background (Blender scenes)");
  auto image_source = std::make_shared<std::string>("folder");
  keys->emplace_back(cmd->add_option("--image-source", *image_source,
                                     "Images at -r R: 'folder' (images_R/, else a larger folder area-resampled) or "
                                     "'largest' (the largest image folder, resized with PIL's bicubic as the original "
                                     "code does; training and ground truth)")
                         ->check(CLI::IsMember({"folder", "largest"})),
                     "image_source");
  std::vector<std::string> method_names;
  std::string method_help = "Training method:";
  for (const MethodInfo& m : training_methods()) {
    method_names.push_back(m.name);
    method_help += fmt::format(" '{}' ({}){}", m.name, m.help, &m == &training_methods().back() ? "" : ",");
  }
  keys->emplace_back(cmd->add_option("--method", *method, method_help)->check(CLI::IsMember(method_names)), "method");
  opt("--iterations", d.iterations, "iterations", "Training iterations");
  opt("--seed", d.seed, "seed", "Seed of every random choice (same seed and input: same model)")
      ->check(not_negative());
  opt("--init", d.init, "init",
      "Initial points: 'dense' (default: stereo depth of the training views fused, as `d2gs init`; reuses "
      "SCENE/{N}_views or MODEL/init), 'sparse' (SIFT points triangulated from the training views), a PLY file, "
      "'random', or 'sfm-all-views' (the dataset's points3D: an ORACLE, it saw the test views)");
  opt("--random-points", d.random_points, "random_points", "Point count of --init random (random pixel rays of the training views, uniform inverse depth within the scene's depth bounds: docs/training.md)");
  opt("--position-lr", d.lr.means, "position_lr", "Initial position learning rate (× scene extent)");
  opt("--position-lr-final", d.position_lr_final, "position_lr_final", "Final position learning rate (× extent)");
  opt("--sh-dc-lr", d.lr.sh_dc, "sh_dc_lr", "SH DC learning rate");
  opt("--sh-rest-lr", d.lr.sh_rest, "sh_rest_lr", "SH rest learning rate");
  opt("--opacity-lr", d.lr.opacity, "opacity_lr", "Opacity learning rate");
  opt("--scaling-lr", d.lr.scales, "scaling_lr", "Scale learning rate");
  opt("--rotation-lr", d.lr.quats, "rotation_lr", "Rotation learning rate");
  opt("--lambda-dssim", d.lambda_dssim, "lambda_dssim", "Weight of 1 − SSIM in the loss");
  auto clamp_grad = std::make_shared<std::string>("exact");
  keys->emplace_back(cmd->add_option("--alpha-clamp-grad", *clamp_grad,
                                     "Gradient through alpha = min(0.99, o·G): 'exact' (0 where clamped) or "
                                     "'pass-through' (as if unclamped: the original rasterizer's rule)")
                         ->check(CLI::IsMember({"exact", "pass-through"})),
                     "alpha_clamp_grad");
  opt("--sh-degree", d.sh_degree, "sh_degree", "Maximum SH degree");
  opt("--densify-from", d.densify_from, "densify_from", "Densify after this iteration");
  opt("--densify-until", d.densify_until, "densify_until", "Densify before this iteration");
  opt("--densify-every", d.densify_every, "densify_every", "Densification interval");
  opt("--densify-grad-threshold", d.densify.grad_threshold, "densify_grad_threshold",
      "Screen-space gradient threshold (NDC units)");
  opt("--opacity-reset-at", d.opacity_reset_at, "opacity_reset_at", "Iterations of the opacity reset")->delimiter(',');
  opt("--drop-rate", d.dropgaussian_max_rate, "dropgaussian_max_rate", "DropGaussian: final drop rate");
  auto preset = std::make_shared<std::string>();
  auto scene_preset = std::make_shared<std::string>();
  cmd->add_option("--preset", *preset,
                  "D²GS preset: 'paper' (the paper's formulas and constants) or 'release' (the authors' code, quirks "
                  "included; its values are the defaults, chosen by measurement: docs/training.md); individual "
                  "flags override it")
      ->check(CLI::IsMember({"paper", "release"}));
  cmd->add_option("--scene-preset", *scene_preset,
                  "D²GS per-scene values of the release, e.g. fern, llff/room, mipnerf360/bicycle (weights, rates, "
                  "far-mask %, DAFE weight)");
  opt("--dd-weight-depth", d.dd_drop.weight_depth, "dd_weight_depth", "D²GS: weight of the depth score");
  opt("--dd-weight-density", d.dd_drop.weight_density, "dd_weight_density", "D²GS: weight of the density score");
  opt("--dd-rate-min", d.dd_drop.rate_min, "dd_rate_min", "D²GS: initial drop rate");
  opt("--dd-rate-max", d.dd_drop.rate_max, "dd_rate_max", "D²GS: final drop rate");
  flag("--dd-compensate", d.dd_drop.compensate, "dd_compensate",
       "D²GS diagnostic: scale kept Gaussians' opacity by 1/(1 − p_i) as DropGaussian does (paper and release: no)");
  opt("--dafe-prior", d.dafe.prior, "dafe_prior_dir",
      "D²GS: folder of per-view prior maps NAME.npy, or 'stereo' (the depth maps of `d2gs init`, kind depth); "
      "default: the model's own depth at iteration 1000");
  auto prior_kind = std::make_shared<std::string>();
  keys->emplace_back(cmd->add_option("--dafe-prior-kind", *prior_kind,
                                     "D²GS: the --dafe-prior maps hold 'disparity' (large = near, default) or 'depth' "
                                     "(0 = no value)")
                         ->check(CLI::IsMember({"depth", "disparity"})),
                     "dafe_prior_kind");
  opt("--dafe-tau", d.dafe.tau, "dafe_tau", "D²GS: far-mask percentage (percentile rule)");
  opt("--dafe-lambda", d.dafe.lambda, "dafe_lambda", "D²GS: DAFE loss weight");
  opt("--save-iterations", d.save_iterations, "save_iterations", "Iterations whose model is saved (default: the last)")
      ->delimiter(',');
  opt("--checkpoint-iterations", d.checkpoint_iterations, "checkpoint_iterations",
      "Iterations whose full training state is saved (chkpntN.bin)")->delimiter(',');
  opt("--test-iterations", d.test_iterations, "test_iterations", "Iterations at which test PSNR/SSIM are logged")
      ->delimiter(',');
  flag("--quiet", d.quiet, "quiet", "No progress line");
  cmd->add_option("--resume", *resume,
                  "Continue from a checkpoint (chkpntN.bin) bit-identically: the same scene, -r, split and training "
                  "options, --iterations at least the checkpoint's (anything else is refused: docs/formats.md)");

  return [cfg, config_file, resume, method, keys, preset, scene_preset, prior_kind, image_source, clamp_grad]() -> int {
    nlohmann::json flags;
    to_json(flags, *cfg);
    flags["method"] = *method;
    flags["image_source"] = *image_source;
    flags["alpha_clamp_grad"] = *clamp_grad;
    flags["dafe_prior_kind"] = prior_kind->empty() ? "disparity" : *prior_kind;
    TrainConfig c;
    if (!config_file->empty()) {
      nlohmann::json j = read_json_file(*config_file);
      for (const char* recorded : {"init_is_oracle", "scene_extent", "split", "images_folder"}) j.erase(recorded);  // saved for the record
      try {
        update_from_json(c, j);
      } catch (const Error& e) {
        fail_file(*config_file, "{}", e.what());
      }
    }
    // Presets apply over the file; explicit flags apply over both.
    if (!preset->empty()) {
      apply_d2gs_preset(c, *preset);
      c.preset = *preset;
    }
    if (!scene_preset->empty()) {
      apply_scene_preset(c, *scene_preset);
      c.scene_preset = *scene_preset;
    }
    nlohmann::json given = nlohmann::json::object();
    for (const auto& [option, key] : *keys)
      if (option->count() > 0) given[key] = flags[key];
    update_from_json(c, given);
    // config.json records the scene absolute, so that eval and imr find it from any working folder.
    if (!c.source.empty()) c.source = std::filesystem::absolute(c.source).lexically_normal().string();
    Trainer trainer(c, *resume);
    trainer.run();
    if (std::filesystem::is_regular_file(std::filesystem::path(c.model_dir) / "results.json"))
      report::write_run_report_or_warn(c.model_dir);
    return 0;
  };
}

}  // namespace d2gs::cli
