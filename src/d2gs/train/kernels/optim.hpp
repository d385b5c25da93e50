#pragma once
// The training step's kernels outside the rasterizer: Adam (adam_kernels.hpp), the L1 loss with its
// gradient (l1_kernels.hpp), SSIM with its gradient (ssim_kernels.hpp), DAFE with its gradient
// (dafe_kernels.hpp), DD-Drop's probabilities (dd_drop_kernels.hpp), the dropout masks
// (dropout_kernels.hpp), the densification statistic and edits (densify_kernels.hpp): through the CPU emulator
// (render/kernels/emulate.hpp) in every build, and on the GPU (train/cuda/optim.cu) when there is one.
// Same arguments and results as Adam::step, l1_loss, Ssim<float>, dafe_loss, dd_drop_probabilities,
// dropgaussian_mask, bernoulli_mask, GradientStats::add, densify_and_prune, prune_by_opacity and reset_opacity;
// host arrays in and out.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "d2gs/core/random.hpp"
#include "d2gs/eval/ssim.hpp"
#include "d2gs/render/kernels/emulate.hpp"
#include "d2gs/scene/camera.hpp"
#include "d2gs/train/adam.hpp"
#include "d2gs/train/densify.hpp"
#include "d2gs/train/dropout.hpp"
#include "d2gs/train/losses.hpp"

namespace d2gs::train_kernels {

// `schedule`: the emulator's order of blocks and threads and its shared-memory visibility (emulate.hpp).
void emulated_adam_step(Gaussians& model, const Gaussians& grads, AdamState& state, const LearningRates& lr,
                        float means_lr, bool skip_opacity = false,
                        render::kernels::emulate::Schedule schedule = render::kernels::emulate::Schedule::Forward);
double emulated_l1_loss(const float* a, const float* b, std::size_t count, float* grad = nullptr, float scale = 1.0f,
                        render::kernels::emulate::Schedule schedule = render::kernels::emulate::Schedule::Forward);

// Ssim<float>::reference(b, ...) and Ssim<float>::evaluate(a, reference, grad, grad_scale); evaluate
// returns the mean SSIM in double (the CPU returns it rounded to float) and, as the CPU, adds its gradient
// to what grad holds (the L1 gradient in the training step), as emulated_l1_loss adds its own.
Ssim<float>::Reference emulated_ssim_reference(
    const float* b, int width, int height, int channels,
    render::kernels::emulate::Schedule schedule = render::kernels::emulate::Schedule::Forward);
double emulated_ssim(const float* a, const Ssim<float>::Reference& reference, float* grad = nullptr,
                     float grad_scale = 1.0f,
                     render::kernels::emulate::Schedule schedule = render::kernels::emulate::Schedule::Forward);
// dropgaussian_mask and bernoulli_mask: the same draws of rng (left n draws on, as the CPU leaves it).
void emulated_dropgaussian_mask(std::size_t n, double rate, Rng& rng, std::vector<float>& multiplier,
                                render::kernels::emulate::Schedule schedule = render::kernels::emulate::Schedule::Forward);
void emulated_bernoulli_mask(const std::vector<float>& probabilities, Rng& rng, std::vector<float>& multiplier,
                             bool compensate = false,
                             render::kernels::emulate::Schedule schedule = render::kernels::emulate::Schedule::Forward);
// dd_drop_probabilities(gaussian_depths(model, camera, options.depth_mode), density_score, options,
// iteration): the depths, their sort (a stable sort of the keys CUB sorts on the GPU) and p_i.
std::vector<float> emulated_dd_drop_probabilities(
    const Gaussians& model, const Camera& camera, const std::vector<float>& density_score, const DdDropOptions& options,
    int iteration, render::kernels::emulate::Schedule schedule = render::kernels::emulate::Schedule::Forward);
// Those probabilities, then bernoulli_mask(them, rng, multiplier, options.compensate) from the device's copy
// (the CPU's draws, rng left where the CPU leaves it); the probabilities too when `probabilities` is set.
void emulated_dd_drop_mask(const Gaussians& model, const Camera& camera, const std::vector<float>& density_score,
                           const DdDropOptions& options, int iteration, Rng& rng, std::vector<float>& multiplier,
                           std::vector<float>* probabilities = nullptr,
                           render::kernels::emulate::Schedule schedule = render::kernels::emulate::Schedule::Forward);
// dafe_loss: the value as a fixed-order double sum; grad (if non-null) += scale · d/da, as the CPU adds.
double emulated_dafe_loss(const float* a, const float* b, int width, int height, int channels,
                          const std::vector<std::uint8_t>& mask, DafeLossForm form, float* grad = nullptr,
                          float scale = 1.0f,
                          render::kernels::emulate::Schedule schedule = render::kernels::emulate::Schedule::Forward);
// stats.add(grad_mean2d_ndc, radii).
void emulated_add_gradient_stats(GradientStats& stats, const std::vector<float>& grad_mean2d_ndc,
                                 const std::vector<int>& radii,
                                 render::kernels::emulate::Schedule schedule = render::kernels::emulate::Schedule::Forward);
// densify_and_prune and prune_by_opacity (densify_pipeline.hpp): the same model, moments, statistics,
// report and rng state as the CPU's.
DensifyReport emulated_densify_and_prune(
    Gaussians& model, AdamState& adam, GradientStats& stats, float scene_extent, const DensifyOptions& options,
    Rng& rng, render::kernels::emulate::Schedule schedule = render::kernels::emulate::Schedule::Forward);
DensifyReport emulated_prune_by_opacity(
    Gaussians& model, AdamState& adam, GradientStats& stats, float min_opacity,
    render::kernels::emulate::Schedule schedule = render::kernels::emulate::Schedule::Forward);
// reset_opacity: the same logits and moments as the CPU's.
void emulated_reset_opacity(Gaussians& model, AdamState& adam, float ceiling = 0.01f,
                            render::kernels::emulate::Schedule schedule = render::kernels::emulate::Schedule::Forward);

// The same on the GPU; d2gs::Error without one.
void device_adam_step(Gaussians& model, const Gaussians& grads, AdamState& state, const LearningRates& lr,
                      float means_lr, bool skip_opacity = false);
double device_l1_loss(const float* a, const float* b, std::size_t count, float* grad = nullptr, float scale = 1.0f);
Ssim<float>::Reference device_ssim_reference(const float* b, int width, int height, int channels);
double device_ssim(const float* a, const Ssim<float>::Reference& reference, float* grad = nullptr,
                   float grad_scale = 1.0f);
void device_dropgaussian_mask(std::size_t n, double rate, Rng& rng, std::vector<float>& multiplier);
void device_bernoulli_mask(const std::vector<float>& probabilities, Rng& rng, std::vector<float>& multiplier,
                           bool compensate = false);
void device_add_gradient_stats(GradientStats& stats, const std::vector<float>& grad_mean2d_ndc,
                               const std::vector<int>& radii);
std::vector<float> device_dd_drop_probabilities(const Gaussians& model, const Camera& camera,
                                                const std::vector<float>& density_score, const DdDropOptions& options,
                                                int iteration);
void device_dd_drop_mask(const Gaussians& model, const Camera& camera, const std::vector<float>& density_score,
                         const DdDropOptions& options, int iteration, Rng& rng, std::vector<float>& multiplier,
                         std::vector<float>* probabilities = nullptr);
double device_dafe_loss(const float* a, const float* b, int width, int height, int channels,
                        const std::vector<std::uint8_t>& mask, DafeLossForm form, float* grad = nullptr,
                        float scale = 1.0f);
DensifyReport device_densify_and_prune(Gaussians& model, AdamState& adam, GradientStats& stats, float scene_extent,
                                       const DensifyOptions& options, Rng& rng);
DensifyReport device_prune_by_opacity(Gaussians& model, AdamState& adam, GradientStats& stats, float min_opacity);
void device_reset_opacity(Gaussians& model, AdamState& adam, float ceiling = 0.01f);

}  // namespace d2gs::train_kernels
