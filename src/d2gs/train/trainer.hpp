#pragma once
// The training loop of 3DGS / DropGaussian / D²GS (method.md §2, §4, §5) on the CPU rasterizer, with
// the original's iteration order: learning-rate schedule, SH degree, camera from a random permutation,
// the method's opacity multiplier (dropout), render, loss (L1 + λ·D-SSIM + the method's terms, e.g. DAFE)
// on the clamped image, backward, densification statistics and edits, opacity reset, Adam step. What
// differs between methods sits behind train/methods/method.hpp; the loop never asks which method it
// runs. Outputs in the layout of the original code. With --device cuda|emulated and a method whose hooks
// the device can stand in for (TrainingMethod::runs_on_device), the whole step runs on the device
// (train/kernels/device_step.hpp), the model coming to the host only for saves, tests, densification,
// the opacity reset and checkpoints; other methods keep their hooks on the host with the rasterizer on the
// device.
#include <filesystem>
#include <functional>
#include <memory>

#include "d2gs/eval/evaluate.hpp"
#include "d2gs/model/gaussians.hpp"
#include "d2gs/scene/scene.hpp"
#include "d2gs/scene/split.hpp"
#include "d2gs/train/config.hpp"
#include "d2gs/train/methods/method.hpp"

namespace d2gs {

struct IterationRecord {
  int iteration = 0;
  double loss = 0, l1 = 0, ssim = 0;  // loss = l1 + λ·(1 − ssim) + Σ weight·value of `terms`
  std::vector<LossTerm> terms;        // the method's loss terms (D²GS: dafe)
  double drop_fraction = 0;  // share of Gaussians masked out this iteration
  std::size_t gaussians = 0;
  double elapsed_s = 0;
};

// The lock file of a run folder: held by d2gs train for the whole run and by d2gs eval while it scores,
// so that neither writes results or renders into a folder the other is working in.
inline constexpr const char* kRunFolderLock = ".d2gs-train.lock";

class Trainer {
public:
  // Loads the scene (training views only) and builds the initial model, or restores `resume_from`.
  explicit Trainer(TrainConfig config, const std::filesystem::path& resume_from = {});
  ~Trainer();
  Trainer(const Trainer&) = delete;
  Trainer& operator=(const Trainer&) = delete;

  // Runs to config.iterations with progress, logs, saves, checkpoints and the final evaluation.
  void run();
  // One iteration (the building block of run(); tests call it directly).
  IterationRecord step();

  int iteration() const;
  const Gaussians& model() const;
  const Scene& scene() const;
  const Split& split() const;
  const TrainConfig& config() const;
  float scene_extent() const;
  bool init_is_oracle() const;  // the initial cloud saw the test views (sfm-all-views)

  // Checkpoint: everything needed to continue bit-identically (model, moments, statistics, random
  // streams, camera queue, the method's state). Written atomically.
  void save_checkpoint(const std::filesystem::path& path) const;

  // Renders and scores the test views with the current model (no dropout).
  EvalSummary evaluate_test_views(const std::filesystem::path& render_dir = {}) const;

  struct State;  // opaque: defined in trainer.cpp

private:
  void save_and_test(int iteration);  // run()'s outputs at `iteration`, called from step()
  IterationRecord device_step();      // step() with the device-resident step (--device cuda|emulated)

  std::unique_ptr<State> s_;
};


}  // namespace d2gs
