#pragma once
// The seam between the training loop (train/trainer.cpp) and a training method: 3DGS, DropGaussian,
// D²GS, and whatever comes next. The loop calls a method's hooks at fixed points of every iteration and
// never asks which method it runs; a method keeps its own state and saves it in checkpoints. The shape
// of LichtFeld Studio's IStrategy and gsplat's Strategy (step_pre_backward, step_post_backward).
//
// One iteration, as the trainer runs it (docs/training.md):
//   camera → prepare() → opacity_multiplier() → render → L1 + λ·(1 − SSIM) + loss_terms() on the
//   clamped image (and the depth and alpha, for a method that uses_depth()) → backward → parameter_terms()
//   → before_update() → densification, then after_densify() → Adam step.
//
// A new method or regulariser is one file here (a TrainingMethod and its make_ function) and its entry
// in registry.cpp (docs/training.md, "Adding a method"); options of its own go into TrainConfig.
// Regularisers (--regularisers) are TrainingMethods too: stacked on the run's method (stack.cpp), their
// opacity multipliers multiply its one, their loss terms add to its terms, and their checkpoint state
// is kept under "NAME/" (the method's own state keeps its plain names).
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "d2gs/core/image.hpp"
#include "d2gs/core/random.hpp"
#include "d2gs/geometry/training_geometry.hpp"
#include "d2gs/model/gaussians.hpp"
#include "d2gs/render/rasterizer.hpp"
#include "d2gs/scene/scene.hpp"
#include "d2gs/scene/split.hpp"
#include "d2gs/train/checkpoint.hpp"
#include "d2gs/train/config.hpp"
#include "d2gs/train/densify.hpp"
#include "d2gs/train/methods/registry.hpp"

namespace d2gs {

// The run a method trains in (valid for the trainer's lifetime).
struct MethodRun {
  const Scene& scene;
  const Split& split;
  std::filesystem::path model_dir;
  // Where the geometry of the training views is looked for (SCENE/{N}_views, MODEL/init).
  std::vector<std::filesystem::path> geometry_dirs;
};

// One iteration, as the hooks before the render see it.
struct MethodStep {
  int iteration = 0;      // t, from 1
  int view = 0;           // the camera: its position in split.train
  const Camera& camera;   // scene.cameras[split.train[view]]
  const Gaussians& model;
  Rng& rng;               // the run's "dropout" stream (checkpointed by the trainer)
  // For methods that render (D²GS's self-prior): the run's rasterizer, every training view's camera (by
  // position in split.train) and this iteration's render options.
  render::Rasterizer& rasterizer;
  const std::vector<render::RenderCamera>& train_cameras;
  render::RenderOptions render_options;
};

// The per-Gaussian opacity multiplier of an iteration's render (dropout), and the share of Gaussians it
// drops (multiplier 0), for the log.
struct OpacityMultiplier {
  const float* values = nullptr;  // N values, or null: all ones
  double drop_fraction = 0.0;
};

// The loss on the clamped prediction, for extra terms (interleaved H×W×C images), and on the render's
// depth and alpha for a method whose uses_depth() is true (null otherwise).
struct MethodLoss {
  const MethodStep& step;
  const float* prediction;  // clamped to [0, 1]
  const Image& target;
  int width = 0, height = 0, channels = 3;
  float* grad;  // d loss / d prediction: each term adds weight · its gradient
  const float* depth = nullptr;  // H×W: Σ w·z, not divided by alpha (render::RenderOutputs::depth)
  const float* alpha = nullptr;  // H×W
  float* grad_depth = nullptr;   // d loss / d depth, d loss / d alpha: each term adds weight · its gradient
  float* grad_alpha = nullptr;
};

// What the device-resident step (--device cuda|emulated, train/kernels/device_step.hpp) does for a method in
// one iteration, in place of its hooks: the opacity multiplier (none, DropGaussian's uniform dropout at
// `rate`, or DD-Drop's from `dd` and the density scores) and the DAFE term on this view's mask. The vectors
// belong to the method and stay valid until its next hook; the device uploads one again only when its
// version changed.
struct DeviceStepPlan {
  bool dropgaussian = false;
  double rate = 0.0;
  bool dd_drop = false;
  DdDropOptions dd;
  const std::vector<float>* density = nullptr;  // the model's size
  std::uint64_t density_version = 0;
  bool dafe = false;
  const std::vector<std::uint8_t>* dafe_mask = nullptr;  // this view's H×W far-region mask; empty: no term yet
  std::uint64_t dafe_mask_version = 0;                   // of every view's masks
  DafeLossForm dafe_form = DafeLossForm::Release;
  float dafe_weight = 0.0f;
};

// A term of the loss: loss += weight · value; logged under `name` (train_log.jsonl).
struct LossTerm {
  std::string name;
  double value = 0.0;
  double weight = 1.0;
};

class TrainingMethod {
public:
  virtual ~TrainingMethod() = default;
  TrainingMethod() = default;
  TrainingMethod(const TrainingMethod&) = delete;
  TrainingMethod& operator=(const TrainingMethod&) = delete;

  virtual const char* name() const = 0;

  // ---- setting up ----
  // The options as the run's identity records them (checkpoint.hpp), before anything is read or
  // written: where two spellings name one run, the method makes them one.
  virtual void describe(TrainConfig& /*as_trained*/, const MethodRun& /*run*/) const {}
  // Throws d2gs::Error naming the problem (the trainer prefixes "CHECKPOINT: cannot resume: ") unless
  // `state`, read from a checkpoint of a run with identity `run` whose model has `gaussians` Gaussians,
  // fits this method and run. The default: no state at all.
  virtual void check_state(const MethodState& state, const RunIdentity& run, std::size_t gaussians) const;
  // Once the run is set up (scene, split, initial model), before a checkpoint is restored. `config` is
  // what config.json records: a method may resolve its options there (D²GS: --dafe-prior stereo → the
  // folder of the depth maps). `training_geometry` builds or finds the training views' geometry.
  virtual void start(TrainConfig& /*config*/, const MethodRun& /*run*/,
                     const std::function<CachedTrainingGeometry()>& /*training_geometry*/) {}

  // ---- every iteration ----
  // Anything before this iteration's render (D²GS: the self-prior at iteration 1000).
  virtual void prepare(const MethodStep& /*step*/) {}
  // The opacity multiplier of this iteration's render.
  virtual OpacityMultiplier opacity_multiplier(const MethodStep& /*step*/) { return {}; }
  // Extra loss terms: each adds weight · its gradient to loss.grad (and, with uses_depth(), to
  // loss.grad_depth / grad_alpha) and is returned.
  virtual std::vector<LossTerm> loss_terms(const MethodLoss& /*loss*/) { return {}; }
  // Whether loss_terms() needs the render's depth and alpha and their gradients. Without it the backward
  // gets no depth or alpha gradient at all, exactly as before the hook existed.
  virtual bool uses_depth() const { return false; }
  // Loss terms on the parameters themselves (a regulariser of the Gaussians' shapes), after the backward on
  // every iteration: each adds weight · its gradient w.r.t. the parameters to `grad` (the render's
  // gradients, the model's shape) and is returned, as loss_terms() does for the image.
  virtual std::vector<LossTerm> parameter_terms(int /*iteration*/, const Gaussians& /*model*/, Gaussians& /*grad*/) {
    return {};
  }
  // After the backward, before densification and the Adam step, on every iteration but the last (whose
  // model is the one saved): edits of the parameters themselves (opacity decay). The Adam moments stay.
  virtual void before_update(int /*iteration*/, Gaussians& /*model*/) {}
  // After densify_and_prune (report.source: where each new row came from) or any other edit of the rows.
  virtual void after_densify(const DensifyReport& /*report*/) {}

  // ---- the device-resident step ----
  // Whether the device's step can stand in for this method's per-iteration hooks (prepare,
  // opacity_multiplier, loss_terms: then none of them is called, device_plan() says what the device does
  // instead, and the method has no before_update()). false (the default): with --device cuda|emulated the
  // trainer keeps the hooks on the host and runs only the rasterizer on the device. after_densify() is
  // called either way.
  virtual bool runs_on_device() const { return false; }
  // Whether device_plan() of iteration t reads step.model's values (the trainer then brings the model to
  // the host first; otherwise step.model has the model's size but values as of its last copy).
  virtual bool needs_host_model(int /*iteration*/) const { return false; }
  virtual DeviceStepPlan device_plan(const MethodStep& /*step*/) { return {}; }

  // ---- checkpoints ----
  virtual MethodState state() const { return {}; }
  // Takes a state that check_state() accepted.
  virtual void restore(MethodState&& /*state*/) {}
};

// Share of zeros in `multiplier` (0 for none).
double drop_fraction(const std::vector<float>& multiplier);

}  // namespace d2gs
