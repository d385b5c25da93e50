#pragma once
// Every training option, with the defaults of method.md §2 (shared by 3DGS, DropGaussian and D²GS).
// The same structure is filled from command-line flags and from a JSON file (`--config`), and the
// effective configuration is saved as MODEL_DIR/config.json.
#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "d2gs/train/adam.hpp"
#include "d2gs/train/densify.hpp"
#include "d2gs/train/dropout.hpp"
#include "d2gs/train/losses.hpp"

namespace d2gs {

enum class Method { Gs3d, DropGaussian, D2gs };
const char* to_string(Method m);
Method method_from_string(const std::string& s);  // "3dgs" | "dropgaussian" | "d2gs"

struct TrainConfig {
  // data
  std::string source;                 // -s
  std::string model_dir;              // -m
  int resolution = 1;                 // -r
  int n_views = 0;                    // 0 = every non-test view
  std::vector<int> train_views, test_views;
  bool white_background = false;

  // method
  Method method = Method::Gs3d;
  int iterations = 10000;
  std::uint64_t seed = 0;

  // initial Gaussians: "dense" (stereo + fusion of the training views), "sparse" (SIFT triangulation of
  // the training views), a PLY path, "random", or "sfm-all-views" (oracle: saw the test views)
  std::string init = "dense";
  // stereo of --init dense / sparse and of --dafe-prior stereo: "sgbm" or "patchmatch" (d2gs init --dense-method)
  std::string init_dense_method = "sgbm";
  int random_points = 10000;

  // optimisation
  LearningRates lr;
  float position_lr_final = 1.6e-6f;  // times the scene extent
  float lambda_dssim = 0.2f;          // L = L1 + λ·(1 − SSIM)
  int sh_degree = 3;
  int sh_increase_every = 1000;

  // densification
  DensifyOptions densify;
  int densify_from = 500;
  int densify_until = 10000;
  int densify_every = 100;
  std::vector<int> opacity_reset_at = {3000, 6000, 9000};

  // DropGaussian
  double dropgaussian_max_rate = 0.2;

  // D²GS: DD-Drop and DAFE (presets.hpp sets groups of these; the names are kept for the record).
  // The defaults are the release preset's values, chosen by measurement on fern (docs/training.md, "Which
  // D²GS preset"); --preset paper switches to the paper's formulas and constants.
  std::string preset;        // "paper", "release" or empty (= the defaults, i.e. the release's values)
  std::string scene_preset;  // e.g. "llff/fern", or empty
  DdDropOptions dd_drop = {.weight_depth = 0.3, .weight_density = 0.7, .depth_mode = DepthMode::ReleaseDot};
  int density_refresh_every = 500;
  bool release_density_cache = true;  // the release's quirk (see method.md §4)
  bool dafe = true;
  std::string dafe_prior_dir;          // folder of per-view depth/disparity maps; "stereo": the init's depths
  PriorKind dafe_prior_kind = PriorKind::Disparity;
  DafeMaskRule dafe_mask_rule = DafeMaskRule::Percentile;
  double dafe_tau = 5.0;               // percent (percentile rule) or fraction (threshold rule)
  DafeLossForm dafe_loss_form = DafeLossForm::Release;
  float dafe_lambda = 1.0f;

  // outputs
  std::vector<int> save_iterations;        // empty = the last iteration only
  std::vector<int> checkpoint_iterations;  // optimiser state for --resume
  std::vector<int> test_iterations;        // test-view PSNR/SSIM logged at these
  int log_every = 10;
  bool quiet = false;

  // Throws d2gs::Error for impossible values, naming the option.
  void validate() const;
};

void to_json(nlohmann::json& j, const TrainConfig& c);
// Reads the keys present in `j` into `c` (others keep their values); an unknown key is an error.
void update_from_json(TrainConfig& c, const nlohmann::json& j);

}  // namespace d2gs
