#include "d2gs/train/trainer.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <optional>
#include <regex>
#include <set>

#include <nlohmann/json.hpp>
#include <omp.h>
#include <spdlog/spdlog.h>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/file_lock.hpp"
#include "d2gs/core/finite.hpp"
#include "d2gs/core/interrupt.hpp"
#include "d2gs/core/random.hpp"
#include "d2gs/core/stage_profile.hpp"
#include "d2gs/eval/ssim.hpp"
#include "d2gs/geometry/training_geometry.hpp"
#include "d2gs/model/ply.hpp"
#include "d2gs/render/activations.hpp"
#include "d2gs/render/device_choice.hpp"
#include "d2gs/render/raster_math.hpp"
#include "d2gs/render/rasterizer.hpp"
#include "d2gs/train/checkpoint.hpp"
#include "d2gs/train/densify.hpp"
#include "d2gs/train/initialize.hpp"
#include "d2gs/train/kernels/device_step.hpp"
#include "d2gs/train/loss_math.hpp"
#include "d2gs/train/losses.hpp"
#include "d2gs/train/methods/method.hpp"
#include "d2gs/train/outputs.hpp"
#include "d2gs/train/progress.hpp"

namespace d2gs {
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

float compute_scene_extent(const Scene& scene, const std::vector<int>& views) {
  glm::dvec3 mean(0.0);
  for (int v : views) mean += scene.cameras[static_cast<std::size_t>(v)].center_world();
  mean /= static_cast<double>(views.size());
  double radius = 0.0;
  for (int v : views) radius = std::max(radius, glm::length(scene.cameras[static_cast<std::size_t>(v)].center_world() - mean));
  if (!(radius > 0.0)) radius = 1.0;  // a single view: the original falls back likewise to a unit radius
  return static_cast<float>(1.1 * radius);
}

}  // namespace

struct Trainer::State {
  TrainConfig cfg;
  Scene scene;
  Split split;
  RunIdentity identity;                       // what the run trains on, recorded in its checkpoints
  std::optional<FileLock> folder_lock;        // held on the model folder for the trainer's lifetime
  std::vector<Image> train_images;            // by position in split.train
  std::vector<render::RenderCamera> train_cameras;
  float extent = 1.0f;
  bool oracle_init = false;

  Gaussians model;
  AdamState adam;
  GradientStats stats;
  render::DeviceChoice device;                // what --device chose
  std::unique_ptr<render::Rasterizer> rasterizer;
  // The device-resident step (--device cuda|emulated and a method that runs_on_device()), null otherwise;
  // while host_stale, the device holds a newer model, moments and statistic than model, adam, stats.
  std::unique_ptr<train_kernels::DeviceStep> resident;
  bool host_stale = false;
  Ssim<float> ssim;
  std::vector<Ssim<float>::Reference> ssim_refs;  // by position in split.train: the images' local statistics
  int iteration = 0;
  int active_sh = 0;
  Rng rng_cameras, rng_dropout, rng_densify;
  std::vector<int> camera_stack;              // positions in split.train still to visit this epoch
  std::unique_ptr<TrainingMethod> method;     // 3DGS, DropGaussian, D²GS, ... (train/methods/)
  double elapsed_before = 0.0;                // seconds spent before a resume

  // per-iteration buffers (reused)
  std::vector<float> pred, grad_rgb, grad_depth, grad_alpha;  // grad_depth, grad_alpha: only for a method that uses_depth()
  Clock::time_point started = Clock::now();
  std::ofstream log;
  // Set by run(): step() then saves the model and scores the test views at the configured iterations, after the
  // backward pass and before densification, the opacity reset and the optimiser step, where train.py does.
  bool outputs = false;

  double elapsed() const { return elapsed_before + std::chrono::duration<double>(Clock::now() - started).count(); }
  fs::path out() const { return cfg.model_dir; }

  // The host's copy of the model, moments and statistic brought up to date from the device.
  void sync_host() {
    if (!resident || !host_stale) return;
    resident->download(model, adam, stats);
    host_stale = false;
  }
  // The host's copy (edited there) back onto the device.
  void sync_device() {
    if (!resident) return;
    resident->upload(model, adam, stats);
    host_stale = false;
  }
};

namespace {

// The lock file of a model folder: one `d2gs train` at a time, released by the kernel when it ends.
constexpr const char* kLockFile = kRunFolderLock;

// Whether `file` is the config.json of a d2gs run (an object naming the method, scene and split), not a
// file of that name some other program left.
bool records_a_d2gs_run(const fs::path& file) {
  std::error_code ec;
  if (!fs::is_regular_file(file, ec)) return false;
  try {
    const nlohmann::json j = nlohmann::json::parse(read_file(file));
    return j.is_object() && j.contains("method") && j["method"].is_string() && j.contains("source") &&
           j["source"].is_string() && j.contains("split") && j["split"].is_object();
  } catch (const std::exception&) {
    return false;
  }
}

// A fresh start in `dir` (already locked): refuse to overwrite a run that saved a model or a checkpoint, or
// a folder d2gs did not make; start again where a run was interrupted before it saved either.
void check_fresh_start(const fs::path& dir, bool started_before) {
  std::error_code ec;
  bool empty = true;
  for (const auto& e : fs::directory_iterator(dir, ec))
    if (e.path().filename() != kLockFile) empty = false;
  if (empty) return;
  if (fs::exists(dir / "results.json", ec))
    fail_file(dir, "already holds a finished training run (use a new folder)");
  if (const auto checkpoints = checkpoints_in(dir); !checkpoints.empty())
    fail_file(dir, "already holds an unfinished training run (continue it with --resume {}, or use a new folder)",
              checkpoints.front().second.string());
  if (fs::exists(dir / "point_cloud", ec) || fs::exists(dir / "test", ec))
    fail_file(dir, "already holds a training run (use a new folder, or --resume CHECKPOINT)");
  if (started_before || records_a_d2gs_run(dir / "config.json")) {
    if (started_before || fs::exists(dir / "train_log.jsonl", ec))
      spdlog::warn("{}: starting the run again: the previous one was interrupted before it saved a model or a checkpoint",
                   dir.string());
    return;
  }
  fail_file(dir, "is not empty and holds no d2gs run; refusing to write into it");
}

// Resuming into `dir` (already locked): a run already there must be the one being resumed.
// A folder without a run's config.json may be resumed into when it holds nothing else than checkpoints
// (one copied there to continue from); anything else is another program's.
void check_resumed_run_in_folder(const fs::path& dir, const TrainConfig& cfg, const Split& split) {
  const fs::path file = dir / "config.json";
  std::error_code ec;
  if (!fs::is_regular_file(file, ec)) {
    static const std::regex checkpoint_name(R"(chkpnt[0-9]+\.bin)");
    for (const auto& e : fs::directory_iterator(dir, ec)) {
      const std::string name = e.path().filename().string();
      if (name != kLockFile && !(e.is_regular_file(ec) && std::regex_match(name, checkpoint_name)))
        fail_file(dir, "is not empty and holds no d2gs run ({} is there); refusing to write into it", name);
    }
    return;
  }
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(read_file(file));
    const bool same_scene = j.at("source").is_string() &&
                            absolute_path(recorded_source(dir, j["source"].get<std::string>()).string()) ==
                                absolute_path(cfg.source);
    if (same_scene && j.at("method") == cfg.method && j.at("seed") == cfg.seed && j.at("resolution") == cfg.resolution &&
        j.at("split").at("train") == split.train && j.at("split").at("test") == split.test)
      return;
  } catch (const nlohmann::json::exception&) {
    fail_file(file, "cannot tell whether the folder holds the run being resumed (not a d2gs config.json)");
  }
  fail_file(dir, "holds another run (scene {}, method {}, seed {}, -r {}, training views {}); resume into the "
                 "checkpoint's run folder or a new one", j["source"].dump(), j["method"].dump(), j["seed"].dump(),
            j["resolution"].dump(), j["split"]["train"].dump());
}

// Creates and locks the model folder, removes what killed writers left there, and checks what it holds.
// The log of a run resumed at iteration `t` (checkpointed at the end of t): the lines up to t, so that the
// iterations trained again after it are not logged twice (a run interrupted after its last checkpoint, or
// a finished run resumed from an earlier one). The first line past t, or one cut short, ends what is kept.
void cut_log_back_to(const fs::path& file, int t) {
  std::error_code ec;
  if (!fs::is_regular_file(file, ec)) return;
  const std::string text = read_file(file);
  std::size_t keep = 0;
  while (keep < text.size()) {
    const std::size_t end = text.find('\n', keep);
    if (end == std::string::npos) break;
    const nlohmann::json line = nlohmann::json::parse(text.begin() + static_cast<std::ptrdiff_t>(keep),
                                                      text.begin() + static_cast<std::ptrdiff_t>(end), nullptr, false);
    if (line.is_discarded() || !line.is_object() ||
        (line.contains("iteration") && line["iteration"].is_number() && line["iteration"].get<double>() > t))
      break;
    keep = end + 1;
  }
  if (keep != text.size()) write_file_atomic(file, text.substr(0, keep));
}

FileLock lock_model_dir(const fs::path& dir, bool resuming) {
  std::error_code ec;
  const bool started_before = fs::exists(dir / kLockFile, ec);
  fs::create_directories(dir, ec);
  if (ec) fail_file(dir, "cannot create the folder ({})", ec.message());
  std::optional<FileLock> lock = FileLock::try_acquire(dir / kLockFile);
  if (!lock) fail_file(dir, "another d2gs train{} is running in this folder", lock_holder_note(dir / kLockFile));
  const auto removed = remove_stale_temporaries(dir);
  if (!removed.empty()) {
    std::string names;
    for (const auto& p : removed) names += (names.empty() ? "" : ", ") + p.lexically_relative(dir).string();
    spdlog::info("{}: removed {} temporary file(s) of writers that were killed: {}", dir.string(), removed.size(), names);
  }
  if (!resuming) check_fresh_start(dir, started_before);
  return std::move(*lock);
}

// Puts a checkpoint's state into the trainer (the scene, split and initial model are already loaded).
void restore(Trainer::State& s, TrainingState&& t) {
  s.iteration = t.iteration;
  s.active_sh = t.active_sh;
  s.adam.step = t.adam_step;
  s.elapsed_before = t.elapsed_s;
  s.camera_stack = std::move(t.camera_stack);
  s.rng_cameras.set_state(t.rng_cameras);
  s.rng_dropout.set_state(t.rng_dropout);
  s.rng_densify.set_state(t.rng_densify);
  s.model = std::move(t.model);
  s.adam.exp_avg = std::move(t.exp_avg);
  s.adam.exp_avg_sq = std::move(t.exp_avg_sq);
  s.stats.restore(std::move(t.grad_sums), std::move(t.grad_counts));
  s.method->restore(std::move(t.method));
}

}  // namespace

Trainer::Trainer(TrainConfig config, const fs::path& resume_from) : s_(std::make_unique<State>()) {
  auto& s = *s_;
  config.validate();
  s.cfg = std::move(config);
  s.method = make_training_method(s.cfg);
  // --device: `cuda` that cannot be had is an error before anything is read or written; `auto` says why it
  // took the CPU. With `cuda` the rasterizer runs on the GPU and every other stage on the CPU, until the
  // CUDA backend runs a whole step (render/device_choice.hpp).
  s.device = render::choose_device(s.cfg.device, render::DeviceWork::Train);  // said in the log once the inputs are checked (below)
  const bool resuming = !resume_from.empty();
  std::error_code ec;
  if (fs::exists(s.cfg.model_dir, ec) && !fs::is_directory(s.cfg.model_dir, ec))
    fail_file(s.cfg.model_dir, "exists and is not a folder");
  {
    SceneAndSplit loaded = load_scene_and_split(s.cfg.source, scene_load_options(s.cfg), split_options(s.cfg));
    s.scene = std::move(loaded.scene);
    s.split = std::move(loaded.split);
  }
  if (s.split.train.empty()) fail("{}: no training views", s.cfg.source);
  // The training-view geometry (init dense/sparse, D²GS's DAFE prior "stereo"): SCENE/{N}_views written
  // by `d2gs init` when it matches, else MODEL/init (built there once, reused on --resume).
  const std::vector<fs::path> geometry_dirs = {training_geometry_dir(s.scene, s.split.train.size()), s.out() / "init"};
  const MethodRun method_run{s.scene, s.split, s.out(), geometry_dirs};
  // What the run trains on, checked against a checkpoint before anything is read from the images or
  // written. The method makes options that name one run alike (D²GS: "stereo" and its folder).
  {
    TrainConfig as_trained = s.cfg;
    s.method->describe(as_trained, method_run);
    s.identity = run_identity(s.scene, s.split, as_trained);
  }
  std::optional<Checkpoint> checkpoint;
  if (resuming) {
    checkpoint = read_checkpoint(resume_from);
    if (const std::string warning = check_resume(resume_from, *checkpoint, s.identity, s.cfg.iterations); !warning.empty())
      spdlog::warn("{}", warning);
    try {
      s.method->check_state(checkpoint->state.method, s.identity, checkpoint->state.model.size());
    } catch (const Error& e) {
      fail_file(resume_from, "cannot resume: {}", e.what());
    }
  }
  const bool new_folder = !fs::exists(s.out(), ec), new_lock = !fs::exists(s.out() / kLockFile, ec);
  s.folder_lock = lock_model_dir(s.out(), resuming);
  // When a later step of the set-up fails (a corrupt image, a bad --init, another run in the folder) a lock
  // file made here goes, and a folder made here goes too when it holds nothing else: neither is left behind,
  // nor taken for an interrupted run; a folder that was there keeps what it held.
  struct RemoveIfLeftEmpty {
    State& s;
    bool new_folder, new_lock;
    bool armed = true;
    ~RemoveIfLeftEmpty() {
      if (!armed) return;
      std::error_code ignored;
      if (new_lock) fs::remove(s.folder_lock->path(), ignored);  // while held (core/file_lock.hpp)
      s.folder_lock.reset();
      if (new_folder) fs::remove(s.out(), ignored);  // only when empty
    }
  } remove_if_left_empty{s, new_folder, new_lock};
  if (resuming) check_resumed_run_in_folder(s.out(), s.cfg, s.split);
  for (int v : s.split.train) {
    s.train_images.push_back(load_image(s.scene, v));
    s.train_cameras.push_back(render::make_render_camera(s.scene.cameras[static_cast<std::size_t>(v)]));
  }
  // The test views are scored at the test iterations and at the end, after the model is saved: one that
  // cannot be decoded would fail the run only then, leaving a folder that neither resumes nor restarts.
  for (int v : s.split.test) (void)load_image(s.scene, v);
  for (const Image& image : s.train_images)
    s.ssim_refs.push_back(s.ssim.reference(image.pixels.data(), image.width, image.height, image.channels));
  s.extent = compute_scene_extent(s.scene, s.split.train);
  s.rasterizer = render::make_rasterizer(s.device);
  s.rng_cameras = Rng::stream(s.cfg.seed, "cameras");
  s.rng_dropout = Rng::stream(s.cfg.seed, "dropout");
  s.rng_densify = Rng::stream(s.cfg.seed, "densify");

  PointCloud init;
  const std::function<CachedTrainingGeometry()> training_geometry = [&s, &geometry_dirs]() {
    TrainingGeometryOptions go;
    go.seed = s.cfg.seed;
    go.dense_method = parse_dense_method(s.cfg.init_dense_method);
    go.patch_match_fusion.max_color_difference = s.cfg.init_color_filter;
    go.patch_match.filter_min_distinctiveness = s.cfg.init_pm_distinctiveness;
    go.patch_match.filter_min_uniqueness = s.cfg.init_pm_uniqueness;
    go.patch_match.filter_uniqueness_step = s.cfg.init_pm_uniqueness_step;
    return obtain_training_geometry(s.scene, s.split.train, go, geometry_dirs, s.out() / "init");
  };
  if (s.cfg.init == "dense" || s.cfg.init == "sparse") {
    const auto g = training_geometry();
    const bool dense = s.cfg.init == "dense" && g.has_dense;
    init = read_point_cloud_ply(dense ? g.dense_ply : g.sparse_ply);
    if (dense && init.size() < 100) {
      spdlog::warn("the fused stereo cloud has only {} points; using the sparse points", init.size());
      init = read_point_cloud_ply(g.sparse_ply);
    }
    spdlog::info("initialising from {} points of the training views' geometry", init.size());
  } else if (s.cfg.init == "sfm-all-views") {
    if (s.scene.sfm_points.empty())
      fail("{}: the scene has no SfM points for --init sfm-all-views; use --init random or --init PLY", s.cfg.source);
    init = s.scene.sfm_points;
    s.oracle_init = true;
    spdlog::warn("initialising from the dataset's all-view SfM points: an ORACLE (it saw the test views)");
  } else if (s.cfg.init == "random") {
    const RandomInitRange range = random_init_depth_range(s.scene, s.split.train, s.extent);
    spdlog::info("random init: {} points, inverse depth uniform between depths {:.3g} and {:.3g} ({})",
                 s.cfg.random_points, range.near, range.far,
                 range.from_dataset_points ? "the dataset's bounds: 0.1 and 99.9 % of its points' depths in the training views"
                                           : "no dataset points: 0.5 and 50 scene extents");
    init = random_point_cloud(s.scene, s.split.train, s.cfg.random_points, range, s.cfg.seed);
  } else {
    init = read_point_cloud_ply(s.cfg.init);
    if (init.empty()) fail_file(s.cfg.init, "the point cloud has no points (0 vertices); nothing to initialise from");
  }
  s.model = gaussians_from_point_cloud(init, s.cfg.sh_degree);
  s.adam = Adam::make_state(s.model);
  s.stats.reset(s.model.size());
  s.method->start(s.cfg, method_run, training_geometry);

  fs::create_directories(s.out());
  if (checkpoint) {
    restore(s, std::move(checkpoint->state));
    checkpoint.reset();
    spdlog::info("resumed from {} at iteration {}", resume_from.string(), s.iteration);
  } else {
    write_point_cloud_ply(s.out() / "input.ply", init);
  }
  if (s.device.device != render::Device::Cpu && s.method->runs_on_device()) {
    s.resident = s.device.device == render::Device::Cuda ? train_kernels::make_device_step()
                                                          : train_kernels::make_emulated_step();
    s.resident->set_training_views(s.train_images, s.ssim_refs);
    s.sync_device();
  }
  if (!s.device.reason.empty()) spdlog::info("--device auto: using the {}: {}", s.device.description, s.device.reason);
  if (s.device.device != render::Device::Cpu)
    spdlog::info("device: {}; {}", s.device.description,
                 s.resident ? "the whole training step on it"
                            : fmt::format("the rasterizer on it, --method {}'s hooks on the CPU", s.cfg.method));
  write_run_config(s.out(), s.cfg, s.scene, s.split, s.extent, s.oracle_init, s.device.device);
  write_cameras_json(s.out(), s.scene, s.split);
  if (s.iteration > 0) cut_log_back_to(s.out() / "train_log.jsonl", s.iteration);
  s.log.open(s.out() / "train_log.jsonl", s.iteration > 0 ? std::ios::app : std::ios::trunc);
  if (!s.log) fail_file(s.out() / "train_log.jsonl", "cannot open for writing");
  s.started = Clock::now();
  remove_if_left_empty.armed = false;
}

Trainer::~Trainer() = default;

int Trainer::iteration() const { return s_->iteration; }
const Gaussians& Trainer::model() const {
  s_->sync_host();
  return s_->model;
}
const Scene& Trainer::scene() const { return s_->scene; }
const Split& Trainer::split() const { return s_->split; }
const TrainConfig& Trainer::config() const { return s_->cfg; }
float Trainer::scene_extent() const { return s_->extent; }
bool Trainer::init_is_oracle() const { return s_->oracle_init; }

namespace {

// The start of an iteration, on either path: its number t, its learning rate of the means, the SH degree, the
// camera (its position in split.train, from a random permutation of the training views per epoch).
struct IterationStart {
  int t = 0;
  float means_lr = 0.0f;
  int view = 0;
};

IterationStart start_iteration(Trainer::State& s) {
  const auto& cfg = s.cfg;
  IterationStart i;
  const int t = i.t = ++s.iteration;
  i.means_lr = static_cast<float>(
      position_lr(cfg.lr.means * s.extent, cfg.position_lr_final * s.extent, t, cfg.iterations));
  if (t % cfg.sh_increase_every == 0) s.active_sh = std::min(s.active_sh + 1, cfg.sh_degree);
  if (s.camera_stack.empty()) {
    s.camera_stack.resize(s.split.train.size());
    for (std::size_t k = 0; k < s.camera_stack.size(); ++k) s.camera_stack[k] = static_cast<int>(k);
  }
  const std::size_t pick = s.rng_cameras.below(s.camera_stack.size());
  i.view = s.camera_stack[pick];
  s.camera_stack.erase(s.camera_stack.begin() + static_cast<std::ptrdiff_t>(pick));
  return i;
}

// The log line of an iteration (every log_every and the last).
void log_iteration(Trainer::State& s, const IterationRecord& rec) {
  const int t = rec.iteration;
  if (t % s.cfg.log_every != 0 && t != s.cfg.iterations) return;
  nlohmann::json line = {{"iteration", t}, {"loss", rec.loss}, {"l1", rec.l1}, {"ssim", rec.ssim}};
  for (const LossTerm& term : rec.terms) line[term.name] = term.value;  // the method's terms (D²GS: dafe)
  line["drop_fraction"] = rec.drop_fraction;
  line["gaussians"] = rec.gaussians;
  line["elapsed_s"] = rec.elapsed_s;
  s.log << line.dump() << '\n';
  s.log.flush();
}

void log_densify(Trainer::State& s, int t, const DensifyReport& report) {
  s.log << nlohmann::json{{"event", "densify"}, {"iteration", t}, {"cloned", report.cloned}, {"split", report.split},
                          {"pruned", report.pruned}, {"gaussians", report.after}}.dump() << '\n';
}

}  // namespace

IterationRecord Trainer::step() {
  auto& s = *s_;
  if (s.resident) return device_step();
  const auto& cfg = s.cfg;
  const profile::Scope profile_step("step");
  const IterationStart start = start_iteration(s);
  const int t = start.t;
  IterationRecord rec;
  rec.iteration = t;
  const float means_lr = start.means_lr;
  const int view = start.view;
  const Image& gt = s.train_images[static_cast<std::size_t>(view)];

  // The method's hooks before the render: its preparations, then this iteration's opacity multiplier.
  render::RenderOptions ro;
  ro.background = s.scene.background;
  ro.sh_degree = s.active_sh;
  ro.alpha_clamp_pass_through = cfg.alpha_clamp_pass_through;
  const MethodStep method_step{t, view, s.scene.cameras[static_cast<std::size_t>(s.split.train[static_cast<std::size_t>(view)])],
                               s.model, s.rng_dropout, *s.rasterizer, s.train_cameras, ro};
  {
    const profile::Scope p("method: prepare");
    s.method->prepare(method_step);
  }
  OpacityMultiplier multiplier;
  {
    const profile::Scope p("method: opacity multiplier");
    multiplier = s.method->opacity_multiplier(method_step);
  }
  rec.drop_fraction = multiplier.drop_fraction;

  // Render and loss on the clamped image.
  const auto& out = s.rasterizer->forward(s.model, multiplier.values, s.train_cameras[static_cast<std::size_t>(view)], ro);
  const std::size_t values = out.rgb.size();
  s.pred.resize(values);
  {
    const profile::Scope p("loss: clamp and L1");
    s.grad_rgb.assign(values, 0.0f);
    float* pred = s.pred.data();
    const float* rgb = out.rgb.data();
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t i = 0; i < static_cast<std::ptrdiff_t>(values); ++i) pred[i] = clamp_unit(rgb[i]);
    rec.l1 = l1_loss(s.pred.data(), gt.pixels.data(), values, s.grad_rgb.data(), 1.0f);
  }
  const Ssim<float>::Reference& gt_stats = s.ssim_refs[static_cast<std::size_t>(view)];
  if (gt_stats.width != out.width || gt_stats.height != out.height || gt_stats.channels != 3)
    fail("iteration {}: the render ({}x{}) and training view {} ({}x{}x{}) differ in size", t, out.width, out.height,
         view, gt_stats.width, gt_stats.height, gt_stats.channels);
  {
    const profile::Scope p("loss: SSIM");
    rec.ssim = s.ssim.evaluate(s.pred.data(), gt_stats, s.grad_rgb.data(), -cfg.lambda_dssim);
  }
  rec.loss = rec.l1 + cfg.lambda_dssim * (1.0 - rec.ssim);
  // Depth and alpha reach the loss terms, and their gradients the backward, only for a method that uses them.
  const bool depth_terms = s.method->uses_depth();
  {
    const profile::Scope p("loss: method's terms");
    if (depth_terms) {
      s.grad_depth.assign(out.depth.size(), 0.0f);
      s.grad_alpha.assign(out.alpha.size(), 0.0f);
    }
    rec.terms = s.method->loss_terms(MethodLoss{method_step, s.pred.data(), gt, out.width, out.height, 3, s.grad_rgb.data(),
                                                depth_terms ? out.depth.data() : nullptr,
                                                depth_terms ? out.alpha.data() : nullptr,
                                                depth_terms ? s.grad_depth.data() : nullptr,
                                                depth_terms ? s.grad_alpha.data() : nullptr});
    for (const LossTerm& term : rec.terms) rec.loss += term.weight * term.value;
  }
  {
    const profile::Scope p("loss: clamp's gradient");
    float* grad = s.grad_rgb.data();
    const float* rgb = out.rgb.data();
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t i = 0; i < static_cast<std::ptrdiff_t>(values); ++i)
      if (clamp_blocks_gradient(rgb[i])) grad[i] = 0.0f;  // clamp: no gradient outside [0, 1]
  }
  if (!std::isfinite(rec.loss)) fail("iteration {}: the loss is not finite ({}); stopping", t, rec.loss);

  auto& grads = s.rasterizer->backward(s.grad_rgb.data(), depth_terms ? s.grad_alpha.data() : nullptr,
                                       depth_terms ? s.grad_depth.data() : nullptr);
  {
    const profile::Scope p("loss: method's parameter terms");
    for (LossTerm& term : s.method->parameter_terms(t, s.model, grads.model)) {
      rec.loss += term.weight * term.value;
      rec.terms.push_back(std::move(term));
    }
  }
  {
    const profile::Scope p("finite checks");
    const auto check = [&](const std::vector<float>& a, const char* name) {
      if (!all_finite(a)) fail("iteration {}: non-finite gradient in {}; stopping", t, name);
    };
    check(grads.model.means, "means");
    check(grads.model.log_scales, "log_scales");
    check(grads.model.quats, "quats");
    check(grads.model.opacity_logits, "opacity_logits");
    check(grads.model.sh_dc, "sh_dc");
    check(grads.model.sh_rest, "sh_rest");
  }

  if (s.outputs) {
    const profile::Scope p("outputs: saves and tests");
    const profile::Paused inside;  // their renders are not training's
    save_and_test(t);
  }

  // The method's edits of the parameters (a regulariser's opacity decay), never after the last save.
  if (t < cfg.iterations) {
    const profile::Scope p("method: before update");
    s.method->before_update(t, s.model);
  }

  // Densification (before the optimiser step, as the original).
  bool skip_step = false, skip_opacity = false;
  // Nothing changes the model after the last iteration's save, so the final evaluation scores the saved model
  // (train.py would still densify there, after saving, to no effect on anything it writes).
  if (t < cfg.densify_until && t < cfg.iterations) {
    {
      const profile::Scope p("densify: statistics");
      s.stats.add(grads.grad_mean2d_ndc, out.radii);
    }
    if (t > cfg.densify_from && t % cfg.densify_every == 0) {
      const profile::Scope p("densify: edits");
      const auto report = densify_and_prune(s.model, s.adam, s.stats, s.extent, cfg.densify, s.rng_densify);
      s.method->after_densify(report);
      skip_step = true;  // the new tensors carry no gradient this iteration
      log_densify(s, t, report);
    }
    if (std::find(cfg.opacity_reset_at.begin(), cfg.opacity_reset_at.end(), t) != cfg.opacity_reset_at.end()) {
      reset_opacity(s.model, s.adam);
      skip_opacity = true;
    }
  }
  if (t < cfg.iterations && !skip_step) {
    const profile::Scope p("Adam");
    Adam::step(s.model, grads.model, s.adam, cfg.lr, means_lr, skip_opacity);
  }

  const profile::Scope profile_checks("parameter checks and log");
  for (const auto* a : {&s.model.means, &s.model.log_scales, &s.model.quats, &s.model.opacity_logits})
    if (!all_finite(*a)) fail("iteration {}: a model parameter became non-finite; stopping", t);

  rec.gaussians = s.model.size();
  rec.elapsed_s = s.elapsed();
  log_iteration(s, rec);
  return rec;
}

// step() with the model on the device: the same order, the method's hooks replaced by what its
// device_plan() asks for (TrainingMethod::runs_on_device), the model brought to the host only where the
// host needs it.
IterationRecord Trainer::device_step() {
  auto& s = *s_;
  const auto& cfg = s.cfg;
  const profile::Scope profile_step("step");
  const IterationStart start = start_iteration(s);
  const int t = start.t;
  IterationRecord rec;
  rec.iteration = t;

  train_kernels::ResidentRender r;
  r.camera = s.train_cameras[static_cast<std::size_t>(start.view)];
  r.stages.active_degree = std::min(s.active_sh, cfg.sh_degree);
  r.stages.alpha_min = render::kAlphaMin;
  for (int c = 0; c < 3; ++c) r.composite.background[c] = s.scene.background[c];
  r.composite.clamp_pass_through = cfg.alpha_clamp_pass_through;
  r.composite.fused_multiply_add = true;  // as render::make_rasterizer's kernel rasterizer
  const Camera& camera = s.scene.cameras[static_cast<std::size_t>(s.split.train[static_cast<std::size_t>(start.view)])];
  DeviceStepPlan plan;
  {
    const profile::Scope p("method: device plan");
    if (s.method->needs_host_model(t)) s.sync_host();
    render::RenderOptions ro;
    ro.background = s.scene.background;
    ro.sh_degree = s.active_sh;
    ro.alpha_clamp_pass_through = cfg.alpha_clamp_pass_through;
    plan = s.method->device_plan(
        MethodStep{t, start.view, camera, s.model, s.rng_dropout, *s.rasterizer, s.train_cameras, ro});
  }
  r.dropgaussian = plan.dropgaussian;
  r.drop_rate = plan.rate;
  train_kernels::ResidentDdDrop dd;
  if (plan.dd_drop) {
    dd.options = plan.dd;
    dd.camera = camera;
    dd.iteration = t;
    dd.density = plan.density;
    dd.density_version = plan.density_version;
    r.dd_drop = &dd;
  }
  train_kernels::ResidentDafe dafe;
  if (plan.dafe) {
    dafe.mask = plan.dafe_mask;
    dafe.mask_version = plan.dafe_mask_version;
    dafe.form = plan.dafe_form;
    dafe.weight = plan.dafe_weight;
    r.dafe = &dafe;
  }
  {
    const profile::Scope p("device: render, losses, backward");
    const train_kernels::ResidentLoss loss =
        s.resident->render_and_backward(static_cast<std::size_t>(start.view), r, s.rng_dropout, cfg.lambda_dssim);
    s.host_stale = true;
    rec.l1 = loss.l1;
    rec.ssim = static_cast<float>(loss.ssim);  // as the CPU's Ssim::evaluate returns it
    rec.drop_fraction = loss.drop_fraction;
    if (plan.dafe) rec.terms.push_back({"dafe", loss.dafe, plan.dafe_weight});
  }
  rec.loss = rec.l1 + cfg.lambda_dssim * (1.0 - rec.ssim);
  for (const LossTerm& term : rec.terms) rec.loss += term.weight * term.value;
  if (!std::isfinite(rec.loss)) fail("iteration {}: the loss is not finite ({}); stopping", t, rec.loss);
  if (!s.resident->gradients_finite()) fail("iteration {}: non-finite gradient; stopping", t);

  if (s.outputs) {
    const profile::Scope p("outputs: saves and tests");
    const profile::Paused inside;
    save_and_test(t);
  }

  bool skip_step = false, skip_opacity = false;
  if (t < cfg.densify_until && t < cfg.iterations) {
    s.resident->add_gradient_stats();
    if (t > cfg.densify_from && t % cfg.densify_every == 0) {
      const profile::Scope p("densify: edits (on the host)");
      s.sync_host();
      const auto report = densify_and_prune(s.model, s.adam, s.stats, s.extent, cfg.densify, s.rng_densify);
      s.method->after_densify(report);
      s.sync_device();
      skip_step = true;
      log_densify(s, t, report);
    }
    if (std::find(cfg.opacity_reset_at.begin(), cfg.opacity_reset_at.end(), t) != cfg.opacity_reset_at.end()) {
      s.sync_host();
      reset_opacity(s.model, s.adam);
      s.sync_device();
      skip_opacity = true;
    }
  }
  if (t < cfg.iterations && !skip_step) {
    const profile::Scope p("Adam");
    s.resident->adam(cfg.lr, start.means_lr, skip_opacity);
    s.host_stale = true;
  }
  if (!s.resident->parameters_finite()) fail("iteration {}: a model parameter became non-finite; stopping", t);

  rec.gaussians = s.resident->size();
  rec.elapsed_s = s.elapsed();
  log_iteration(s, rec);
  return rec;
}

void Trainer::save_checkpoint(const fs::path& path) const {
  s_->sync_host();
  const auto& s = *s_;
  TrainingState t;
  t.iteration = s.iteration;
  t.iterations = s.cfg.iterations;
  t.active_sh = s.active_sh;
  t.adam_step = s.adam.step;
  t.elapsed_s = s.elapsed();
  t.camera_stack = s.camera_stack;
  t.rng_cameras = s.rng_cameras.state();
  t.rng_dropout = s.rng_dropout.state();
  t.rng_densify = s.rng_densify.state();
  t.model = s.model;
  t.exp_avg = s.adam.exp_avg;
  t.exp_avg_sq = s.adam.exp_avg_sq;
  t.grad_sums = s.stats.sums();
  t.grad_counts = s.stats.counts();
  t.method = s.method->state();
  write_checkpoint(path, s.identity, t);
}

EvalSummary Trainer::evaluate_test_views(const fs::path& render_dir) const {
  s_->sync_host();
  EvalOptions eo;
  eo.render_dir = render_dir;
  return evaluate_views(s_->model, s_->scene, s_->split.test, eo);
}

// Saves and test metrics at iteration t see the model before that iteration's densification, opacity reset and
// optimiser step, as in the original (a test right after an opacity reset would score a faded model).
void Trainer::save_and_test(int t) {
  auto& s = *s_;
  const auto& cfg = s.cfg;
  const auto listed = [t](const std::vector<int>& at) { return std::find(at.begin(), at.end(), t) != at.end(); };
  const bool saves = cfg.save_iterations.empty() ? t == cfg.iterations : listed(cfg.save_iterations);
  // A --stop-at iteration is scored too, so that a stopped run says where it stands.
  const bool tests = listed(cfg.test_iterations) || (t == cfg.stop_at && t < cfg.iterations);
  if (saves || tests) s.sync_host();
  if (saves) write_gaussians_ply(s.out() / "point_cloud" / fmt::format("iteration_{}", t) / "point_cloud.ply", s.model);
  if (tests) {
    const auto e = evaluate_test_views();
    s.log << nlohmann::json{{"event", "test"}, {"iteration", t}, {"psnr", e.psnr}, {"ssim", e.ssim}}.dump() << '\n';
    s.log.flush();
    if (!cfg.quiet) spdlog::info("iteration {}: test PSNR {:.3f} SSIM {:.4f}", t, e.psnr, e.ssim);
  }
}

void Trainer::run() {
  auto& s = *s_;
  const auto& cfg = s.cfg;
  const std::set<int> checkpoints(cfg.checkpoint_iterations.begin(), cfg.checkpoint_iterations.end());
  const int start = s.iteration;
  // d2gs -q (errors only) silences the progress line as train --quiet does.
  TrainingProgress progress(cfg.method, start, cfg.iterations,
                            cfg.quiet || !spdlog::default_logger()->should_log(spdlog::level::info));
  s.outputs = true;  // saves and test metrics, from step()
  profile::reset();
  // --stop-at: the same schedule, cut after that iteration (a checkpoint there, so that --resume continues).
  const bool stops_early = cfg.stop_at > 0 && cfg.stop_at < cfg.iterations && start < cfg.stop_at;
  const int end = stops_early ? cfg.stop_at : cfg.iterations;
  while (s.iteration < end) {
    if (interrupt_signal() != 0) check_interrupted(fmt::format("at iteration {} of {}", s.iteration, cfg.iterations).c_str());
    const IterationRecord rec = step();
    const int t = rec.iteration;
    if (checkpoints.count(t) || (stops_early && t == end)) save_checkpoint(s.out() / fmt::format("chkpnt{}.bin", t));
    progress.update(t, rec.loss, rec.gaussians, s.elapsed());
  }
  s.outputs = false;
  s.sync_host();
  progress.finish();
  if (profile::enabled()) {
    const std::string table = profile::format_table(profile::totals(), "step");
    if (!table.empty())  // asked for by the environment: printed even with --quiet
      std::fprintf(stderr, "D2GS_PROFILE: wall time per stage, iterations %d-%d, %d OpenMP threads\n%s", start + 1,
                   end, omp_get_max_threads(), table.c_str());
  }
  if (stops_early) {
    spdlog::info("stopped at iteration {} of {} (--stop-at); continue with --resume {}", end, cfg.iterations,
                 (s.out() / fmt::format("chkpnt{}.bin", end)).string());
    return;
  }
  // Resumed from the checkpoint of the run's last iteration (check_resume allows no other at that
  // iteration): nothing to train, and the model is the final one, since the last iteration changes nothing
  // after its save. Save it where that save is missing, so that results.json names a model that exists.
  if (start == cfg.iterations) {
    const fs::path ply = s.out() / "point_cloud" / fmt::format("iteration_{}", start) / "point_cloud.ply";
    const bool saved_at_end = cfg.save_iterations.empty() ||
                              std::find(cfg.save_iterations.begin(), cfg.save_iterations.end(), start) != cfg.save_iterations.end();
    std::error_code ec;
    if (saved_at_end && !fs::exists(ply, ec)) write_gaussians_ply(ply, s.model);
  }
  // Final evaluation on the held-out views, in the original render.py layout.
  if (!s.split.test.empty()) {
    const auto e = evaluate_test_views(s.out() / "test" / fmt::format("ours_{}", s.iteration));
    write_results_json(s.out(), e, s.scene,
                       {.method = cfg.method, .iteration = s.iteration, .gaussians = s.model.size(),
                        .init_is_oracle = s.oracle_init, .train_seconds = s.elapsed(),
                        .device = render::to_string(s.device.device)});
    if (!cfg.quiet) std::fprintf(stdout, "%s", format_table(e).c_str());
  }
}

}  // namespace d2gs
