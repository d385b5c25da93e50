#pragma once
// A training step that keeps the model, its Adam moments and the densification statistic in the device's
// memory (issue 27's device-resident step): one interface, two executions, as the rasterizer's stages
// (render/kernels/stages.hpp): the GPU (make_device_step, train/cuda/resident_step.cu) and the CPU emulation
// of the same kernels and host code (make_emulated_step), which CI runs. The implementation is
// resident_step.hpp's ResidentStep, written once over the backend.
//
// Per step only scalars cross to the host: the number of intersections, the L1 and SSIM sums, the dropout
// stream's state after its draws and the finite checks' flags. The trainer keeps the order of its CPU step
// and calls render_and_backward(), gradients_finite(), add_gradient_stats() while densifying, adam(),
// parameters_finite(); download() and upload() where the host needs the model (saves and tests,
// densification, the opacity reset, checkpoints).
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "d2gs/core/image.hpp"
#include "d2gs/core/random.hpp"
#include "d2gs/eval/ssim.hpp"
#include "d2gs/model/gaussians.hpp"
#include "d2gs/render/kernels/emulate.hpp"
#include "d2gs/render/kernels/stages.hpp"
#include "d2gs/render/rasterizer.hpp"
#include "d2gs/train/adam.hpp"
#include "d2gs/scene/camera.hpp"
#include "d2gs/train/densify.hpp"
#include "d2gs/train/dropout.hpp"
#include "d2gs/train/losses.hpp"

namespace d2gs::train_kernels {

// DD-Drop's multiplier (dropout.hpp: bernoulli_mask of dd_drop_probabilities(gaussian_depths(model, camera,
// options.depth_mode), density, options, iteration)). `density` (host, the model's size) is uploaded when
// density_version differs from the last upload's.
struct ResidentDdDrop {
  DdDropOptions options;
  Camera camera;  // the training view's
  int iteration = 0;
  const std::vector<float>* density = nullptr;
  std::uint64_t density_version = 0;
};

// The DAFE term (losses.hpp: dafe_loss on the clamped render, weight · its gradient added): the view's H×W
// mask (host; uploaded with every view's when mask_version differs from the last upload's; empty: no term
// yet, value 0).
struct ResidentDafe {
  const std::vector<std::uint8_t>* mask = nullptr;
  std::uint64_t mask_version = 0;
  DafeLossForm form = DafeLossForm::Release;
  float weight = 0.0f;
};

// One step's render: the camera, the stages' and compositing's options, the opacity multiplier
// (DropGaussian's uniform dropout at drop_rate or DD-Drop's, drawn from the caller's dropout stream, or
// none) and the method's DAFE term (or none).
struct ResidentRender {
  render::RenderCamera camera;
  render::kernels::StageOptions stages;
  render::kernels::CompositeOptions composite;
  bool dropgaussian = false;
  double drop_rate = 0.0;
  const ResidentDdDrop* dd_drop = nullptr;
  const ResidentDafe* dafe = nullptr;
};

struct ResidentLoss {
  double l1 = 0.0;    // mean |pred − gt|
  double ssim = 0.0;  // mean SSIM (double; the CPU rounds it to float)
  double dafe = 0.0;  // the DAFE term's value (0 without one)
  double drop_fraction = 0.0;  // share of zeros in the opacity multiplier (0 without one)
};

class DeviceStep {
public:
  virtual ~DeviceStep() = default;
  virtual const char* name() const = 0;
  // The training views (RGB, interleaved) and their SSIM references (Ssim<float>::reference), uploaded once.
  virtual void set_training_views(const std::vector<Image>& images,
                                  const std::vector<Ssim<float>::Reference>& refs) = 0;
  // The model, its moments and statistic into the device's memory (replacing what was there), and back.
  virtual void upload(const Gaussians& model, const AdamState& adam, const GradientStats& stats) = 0;
  virtual void download(Gaussians& model, AdamState& adam, GradientStats& stats) = 0;
  virtual std::size_t size() const = 0;
  // The mask, the render of training view `view`, its losses (L1 + lambda_dssim · (1 − SSIM) and the DAFE
  // term on the render clamped to [0, 1]) and the backward into the model's gradients, as Trainer::step.
  virtual ResidentLoss render_and_backward(std::size_t view, const ResidentRender& render, Rng& dropout_rng,
                                           float lambda_dssim) = 0;
  // Whether every gradient of the last render_and_backward() is finite; whether the parameters the trainer
  // guards (means, scales, rotations, opacities) are.
  virtual bool gradients_finite() = 0;
  virtual bool parameters_finite() = 0;
  // GradientStats::add of the last backward (its mean2d gradient in the CPU's NDC convention, the radii).
  virtual void add_gradient_stats() = 0;
  // Adam::step with the last backward's gradients.
  virtual void adam(const LearningRates& lr, float means_lr, bool skip_opacity) = 0;
};

// The kernels and the host code run on the CPU by the emulator (render/kernels/emulate.hpp).
std::unique_ptr<DeviceStep> make_emulated_step(
    render::kernels::emulate::Schedule schedule = render::kernels::emulate::Schedule::Forward);
// On the GPU; d2gs::Error without one.
std::unique_ptr<DeviceStep> make_device_step();

}  // namespace d2gs::train_kernels
