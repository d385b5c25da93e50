#pragma once
// Every training option, with the defaults of method.md §2 (shared by 3DGS, DropGaussian and D²GS).
// Each option is declared once in options.cpp (name = config.json key = flag, help, range), from which
// the command line, the JSON reading and writing and the per-option checks are made; the effective
// configuration is saved as MODEL_DIR/config.json.
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "d2gs/render/device_choice.hpp"
#include "d2gs/train/adam.hpp"
#include "d2gs/train/densify.hpp"
#include "d2gs/train/dropout.hpp"
#include "d2gs/train/losses.hpp"
#include "d2gs/scene/scene.hpp"
#include "d2gs/scene/split.hpp"

namespace d2gs {

struct TrainConfig {
  // data
  std::string source;                 // -s
  std::string model_dir;              // -m (config.json key model_path)
  int resolution = 1;                 // -r
  int n_views = 0;                    // 0 = every non-test view
  std::vector<int> train_views, test_views;
  bool white_background = false;
  // Training and test images: the largest folder resized with PIL's bicubic as the original code does
  // (the default, issue 23), or the prepared images_R/ folder (scene.hpp, ImageSource). Eval scores against
  // the same source; a config.json without the key (runs from before the option) means Folder.
  ImageSource image_source = kDefaultImageSource;

  // method
  std::string method = "3dgs";  // a name of train/methods/registry.cpp: 3dgs, dropgaussian, d2gs
  int iterations = 10000;
  std::uint64_t seed = 0;
  // The backend (render/device_choice.hpp): "cpu", "cuda" or "auto" (CUDA when a device exists and the
  // CUDA backend runs a whole step, else the CPU, saying why). Not part of a run's identity.
  render::DeviceRequest device = render::DeviceRequest::Auto;

  // initial Gaussians: "dense" (stereo + fusion of the training views), "sparse" (SIFT triangulation of
  // the training views), a PLY path, "random", or "sfm-all-views" (oracle: saw the test views)
  std::string init = "dense";
  // stereo of --init dense / sparse and of --dafe-prior stereo: "patchmatch" or "sgbm" (d2gs init --dense-method;
  // docs/benchmarks.md, "What the far background is worth")
  std::string init_dense_method = "patchmatch";
  // PatchMatch fusion's colour test (patch_match_fusion.hpp, max_color_difference): 0 = off; SGBM ignores it
  double init_color_filter = 0.10;
  // PatchMatch's distinctiveness test (patch_match.hpp, filter_min_distinctiveness): 0 = off
  double init_pm_distinctiveness = 0.0;
  // PatchMatch's uniqueness test (patch_match.hpp, filter_min_uniqueness): 0 = off; on (0.1) by default since issue 22
  double init_pm_uniqueness = 0.1;
  // Its sampling step along the epipolar line, in window radii (patch_match.hpp, filter_uniqueness_step)
  double init_pm_uniqueness_step = 1.0;
  int random_points = 10000;

  // optimisation
  LearningRates lr;
  float position_lr_final = 1.6e-6f;  // times the scene extent
  float lambda_dssim = 0.2f;          // L = L1 + λ·(1 − SSIM)
  // Gradient through the rasterizer's alpha clamp min(0.99, o G): false = its derivative (0 where the clamp
  // is active), true = as if unclamped, the original rasterizer's rule (render/raster_math.hpp).
  bool alpha_clamp_pass_through = false;
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
  std::string preset;        // "paper", "release", "plus" or empty (= the defaults, i.e. the release's values)
  std::string scene_preset;  // e.g. "llff/fern", or empty
  DdDropOptions dd_drop = {.weight_depth = 0.3, .weight_density = 0.7, .depth_mode = DepthMode::ReleaseDot,
                           .release_density_cache = true};
  DafeOptions dafe;

  // Regularisers stacked on any method (train/methods/registry.cpp: opacity-noise, opacity-decay), in
  // this order after the method; issue 25's levers. Their options:
  std::vector<std::string> regularisers;
  // opacity-noise (Co-Adaptation of 3DGS, NeurIPS 2025): o·(1 + ε), ε ~ N(0, σ²) clipped to [−σ, σ],
  // at most 1, in training renders only.
  double opacity_noise_sigma = 0.2;
  // opacity-decay (Binocular3DGS, NeurIPS 2024): sigmoid(logit) × factor after every iteration past
  // --densify-from.
  double opacity_decay_factor = 0.995;
  // stereo-depth: the weight of the disparity L1 towards the training views' stereo depth (losses.hpp).
  // 0.05 puts a typical relative disparity error of 0.1–0.3 at a few tenths of the L1 colour loss; chosen
  // a priori, not tuned on a scene.
  double stereo_depth_lambda = 0.05;
  // anisotropy (PhysGaussian, CVPR 2024): λ · mean max(0, ln(s_max / s_min) − ln r). r = 10 is
  // PhysGaussian's and TLC-Calib's ratio; λ = 1 gives every Gaussian beyond it a log-scale gradient of ±1/N
  // (chosen a priori, not tuned on a scene).
  double anisotropy_ratio = 10.0;
  double anisotropy_lambda = 1.0;
  // scale-l1 (3DGS-MCMC, NeurIPS 2024): λ · mean of the N×3 activated scales; λ = 0.01 is 3DGS-MCMC's default
  // (its scenes are in COLMAP units, like ours; not tuned on a scene).
  double scale_l1_lambda = 0.01;

  // outputs
  std::vector<int> save_iterations;        // empty = the last iteration only
  std::vector<int> checkpoint_iterations;  // optimiser state for --resume
  std::vector<int> test_iterations;        // test-view PSNR/SSIM logged at these
  int stop_at = 0;  // > 0: stop after this iteration of the schedule (checkpoint + test metrics), resumable
  int log_every = 10;
  bool quiet = false;

  // Throws d2gs::Error for impossible values, naming the option: the method's name, each option's range
  // (options.cpp), then what ties options together (the DD-Drop rates, the iterations of saves and
  // tests), an --init that is neither a keyword nor an existing file, a model folder that cannot be
  // created (a path under a file).
  void validate() const;
};

// The keys a run's config.json records beside the options (the split, the scene extent, the device used, ...): a
// --config file or an experiment may hold them, and they are not read back as options.
inline constexpr const char* kRecordedKeys[] = {"init_is_oracle", "scene_extent", "split",
                                                "images_folder",  "device_used",  "cpu_tile_level"};

// How the run's scene is loaded (resolution, background, image source) and split into views.
SceneLoadOptions scene_load_options(const TrainConfig& c);
SplitOptions split_options(const TrainConfig& c);

// Every option under its name (options.hpp).
void to_json(nlohmann::json& j, const TrainConfig& c);
// Reads the keys present in `j` into `c` (others keep their values), an option's former name as its
// name. An unknown key, a value of the wrong type, a fraction for an integer option and a number
// outside its option's type (never wrapped or truncated) are errors "key 'NAME': problem", and leave `c`
// as it was; callers reading a file prefix its name. The options' own ranges are validate()'s, as for
// the command line. With `recorded` = Ignore, the keys of kRecordedKeys are skipped (a saved config.json).
enum class RecordedKeys { Refuse, Ignore };
void update_from_json(TrainConfig& c, const nlohmann::json& j, RecordedKeys recorded = RecordedKeys::Refuse);

// A run's recorded config.json `recorded`, read into `c`: the options it lacks take the value the run
// was trained with (options.hpp, value_when_absent: a default changed since is not what it used). Throws
// d2gs::Error (callers prefix the file's name) when `method` or `source` is missing, or a value is of the
// wrong type or outside its option's range (as d2gs train checks them).
void take_recorded_run_config(TrainConfig& c, const nlohmann::json& recorded);

// `p` absolute, with the links and dot segments of its existing part resolved (std::filesystem's weakly
// canonical form; the plain absolute form when that fails): how a run records and compares paths. `p` must
// not be empty.
std::string absolute_path(const std::string& p);

// The scene folder recorded in a run's config.json. d2gs train records it absolute; a relative one (an
// older run, a hand-written file) is taken relative to the run folder `model_dir` when that exists there,
// else relative to the working folder.
std::filesystem::path recorded_source(const std::filesystem::path& model_dir, const std::string& source);

}  // namespace d2gs
