#pragma once
// The host side of the DD-Drop probability, dropout-mask and densification-statistic kernels over a
// backend of render/kernels/pipeline.hpp, written once (CI runs it through the emulator). Host arrays in
// and out, except that DD-Drop's probabilities can go on to the mask kernel without leaving the device.
#include <algorithm>
#include <array>
#include <cstdint>
#include <utility>
#include <vector>

#include "d2gs/core/error.hpp"
#include "d2gs/core/random.hpp"
#include "d2gs/render/kernels/block.hpp"
#include "d2gs/model/gaussians.hpp"
#include "d2gs/scene/camera.hpp"
#include "d2gs/train/densify.hpp"
#include "d2gs/train/dropout.hpp"
#include "d2gs/train/kernels/dd_drop_kernels.hpp"
#include "d2gs/train/kernels/densify_kernels.hpp"
#include "d2gs/train/kernels/dropout_kernels.hpp"

namespace d2gs::train_kernels {

// The jump table of DropoutMaskKernel (computed once).
inline const std::array<uint64_t, 4 * kJumpBits>& dropout_jump_table() {
  static const std::array<uint64_t, 4 * kJumpBits> table = [] {
    const std::vector<uint64_t> t = xoshiro_jump_table(kDrawsPerThread, kJumpBits);
    std::array<uint64_t, 4 * kJumpBits> a{};
    std::copy(t.begin(), t.end(), a.begin());
    return a;
  }();
  return table;
}

// What the dropout mask kernel keeps in the backend's memory between calls: the jump table (uploaded
// once) and the stream's state after the draws (read back: the host's Rng goes on from it).
template <class Backend>
struct DropoutMaskBuffers {
  typename Backend::template Array<uint64_t> jumps, end_state;
  bool jumps_uploaded = false;
};

// dropgaussian_mask (probabilities null) or bernoulli_mask of the n probabilities at `probabilities`, an
// array of the backend (device memory), into `multiplier` (n values of the backend's memory): the same
// multipliers from the same draws, and rng left where the CPU leaves it (n draws on).
template <class Backend>
void dropout_mask_into(Backend& backend, DropoutMaskBuffers<Backend>& buffers, std::size_t n,
                       const float* probabilities, double rate, bool compensate, Rng& rng, float* multiplier) {
  if (n == 0) return;
  const long long chunks = (static_cast<long long>(n) + kDrawsPerThread - 1) / kDrawsPerThread;
  if (n > static_cast<std::size_t>(1u << 31) - 1 || chunks >= (1LL << kJumpBits))
    fail("dropout kernel: {} Gaussians exceed the int32 indices", n);
  if (!buffers.jumps_uploaded) {
    const auto& table = dropout_jump_table();
    backend.upload(buffers.jumps, table.data(), table.size());
    buffers.jumps_uploaded = true;
  }
  buffers.end_state.resize(4);
  DropoutMaskArgs a;
  a.n = static_cast<int>(chunks);
  a.count = static_cast<int>(n);
  const Rng::State before = rng.state();
  for (int k = 0; k < 4; ++k) a.state[k] = before.words[k];
  a.jumps = buffers.jumps.data();
  if (probabilities) {
    a.probabilities = probabilities;
    a.compensate = compensate;
  } else {
    a.rate = rate;
    a.keep_scale = static_cast<float>(1.0 / (1.0 - rate));
  }
  a.multiplier = multiplier;
  a.end_state = buffers.end_state.data();
  render::kernels::launch_per_item<DropoutMaskKernel>(backend, chunks, a);
  std::vector<uint64_t> after;
  backend.download(after, buffers.end_state, 4);
  Rng::State state = before;
  for (int k = 0; k < 4; ++k) state.words[k] = after[static_cast<std::size_t>(k)];
  rng.set_state(state);
}

// The same into a host vector.
template <class Backend>
void dropout_mask_of(Backend& backend, std::size_t n, const float* probabilities, double rate, bool compensate,
                     Rng& rng, std::vector<float>& multiplier) {
  multiplier.resize(n);
  if (n == 0) return;
  DropoutMaskBuffers<Backend> buffers;
  typename Backend::template Array<float> out;
  out.resize(n);
  dropout_mask_into(backend, buffers, n, probabilities, rate, compensate, rng, out.data());
  backend.download(multiplier, out, n);
}

// The same with host probabilities (null: DropGaussian's mask).
template <class Backend>
void dropout_mask(Backend& backend, std::size_t n, const float* probabilities, double rate, bool compensate, Rng& rng,
                  std::vector<float>& multiplier) {
  typename Backend::template Array<float> p;
  if (probabilities && n > 0) backend.upload(p, probabilities, n);
  dropout_mask_of(backend, n, probabilities && n > 0 ? p.data() : nullptr, rate, compensate, rng, multiplier);
}

template <class Backend>
void dropgaussian_mask(Backend& backend, std::size_t n, double rate, Rng& rng, std::vector<float>& multiplier) {
  if (!(rate >= 0.0 && rate < 1.0)) fail("DropGaussian: rate {} outside [0, 1)", rate);
  dropout_mask(backend, n, nullptr, rate, false, rng, multiplier);
}

template <class Backend>
void bernoulli_mask(Backend& backend, const std::vector<float>& probabilities, Rng& rng, std::vector<float>& multiplier,
                    bool compensate) {
  dropout_mask(backend, probabilities.size(), probabilities.data(), 0.0, compensate, rng, multiplier);
}

// GradientStats::add(grad_mean2d_ndc, radii).
template <class Backend>
void add_gradient_stats(Backend& backend, GradientStats& stats, const std::vector<float>& grad_mean2d_ndc,
                        const std::vector<int>& radii) {
  const std::size_t n = stats.size();
  if (grad_mean2d_ndc.size() != 2 * n || radii.size() != n)
    fail("gradient statistics: {} gradients / {} radii for {} Gaussians", grad_mean2d_ndc.size() / 2, radii.size(), n);
  if (n == 0) return;
  if (n > static_cast<std::size_t>(1u << 31) - 1) fail("gradient statistics kernel: {} Gaussians exceed int32", n);
  typename Backend::template Array<float> grad, sum, count;
  typename Backend::template Array<int> r;
  backend.upload(grad, grad_mean2d_ndc.data(), 2 * n);
  backend.upload(r, radii.data(), n);
  backend.upload(sum, stats.sums().data(), n);
  backend.upload(count, stats.counts().data(), n);
  GradientStatsArgs a;
  a.n = static_cast<int>(n);
  a.grad_mean2d_ndc = grad.data();
  a.radii = r.data();
  a.sum = sum.data();
  a.count = count.data();
  render::kernels::launch_per_item<GradientStatsKernel>(backend, static_cast<long long>(n), a);
  std::vector<float> sums, counts;
  backend.download(sums, sum, n);
  backend.download(counts, count, n);
  stats.restore(std::move(sums), std::move(counts));
}

// DD-Drop's probabilities on the backend: dd_drop_probabilities(gaussian_depths(model, camera, mode),
// density_score, options, iteration), kept in the backend's memory for the mask (mask()) and copied out on
// request (download()). The density scores (the host's kNN refresh and cache) are uploaded per call.
template <class Backend>
class DdDropPipeline {
public:
  explicit DdDropPipeline(Backend& backend) : backend_(backend) {}

  void probabilities(const Gaussians& model, const Camera& camera, const std::vector<float>& density_score,
                     const DdDropOptions& options, int iteration) {
    const std::size_t n = model.size();
    if (density_score.size() != n) fail("DD-Drop: {} density scores for {} Gaussians", density_score.size(), n);
    if (n > static_cast<std::size_t>(1u << 31) - 1) fail("DD-Drop kernels: {} Gaussians exceed int32", n);
    n_ = n;
    if (n == 0) return;
    backend_.upload(means_, model.means.data(), 3 * n);
    backend_.upload(density_, density_score.data(), n);
    probabilities_of(means_.data(), density_.data(), n, camera, options, iteration);
  }

  // The same from arrays of the backend: the n means (n x 3) and density scores.
  void probabilities_of(const float* means, const float* density_score, std::size_t n, const Camera& camera,
                        const DdDropOptions& options, int iteration) {
    if (n > static_cast<std::size_t>(1u << 31) - 1) fail("DD-Drop kernels: {} Gaussians exceed int32", n);
    n_ = n;
    if (n == 0) return;
    depth_.resize(n);
    keys_.resize(n);
    keys_sorted_.resize(n);
    index_.resize(n);
    index_sorted_.resize(n);
    probabilities_.resize(n);
    GaussianDepthArgs d;
    d.n = static_cast<int>(n);
    d.means = means;
    d.euclidean = options.depth_mode == DepthMode::Euclidean;
    const glm::dvec3 c = camera.center_world();
    const glm::dvec3 axis = camera.R_world_to_cam[2];  // glm is column-major: the third column
    for (int k = 0; k < 3; ++k) {
      d.centre[k] = c[k];
      d.axis[k] = axis[k];
    }
    d.depth = depth_.data();
    d.keys = keys_.data();
    d.index = index_.data();
    render::kernels::launch_per_item<GaussianDepthKernel>(backend_, n, d);
    // The ranks 0, ⌊0.33·N⌋, ⌊0.67·N⌋ and N − 1 of the depths: their keys sorted (32 bits).
    backend_.sort_pairs(keys_, keys_sorted_, index_, index_sorted_, n, 32);
    DdDropProbabilityArgs p;
    p.n = static_cast<int>(n);
    p.depth = depth_.data();
    p.sorted_keys = keys_sorted_.data();
    p.near_rank = static_cast<int>(tertile_rank(static_cast<long long>(n), kNearTertile));
    p.far_rank = static_cast<int>(tertile_rank(static_cast<long long>(n), kFarTertile));
    p.density_score = density_score;
    p.terms = dd_drop_terms(options, iteration);
    p.probabilities = probabilities_.data();
    render::kernels::launch_per_item<DdDropProbabilityKernel>(backend_, n, p);
  }

  // The probabilities of the last call, in the backend's memory (n values).
  const float* device_probabilities() { return probabilities_.data(); }

  // The probabilities of the last probabilities() call.
  std::vector<float> download() {
    std::vector<float> out;
    backend_.download(out, probabilities_, n_);
    return out;
  }

  // bernoulli_mask of them (the CPU's draws of rng), without copying them to the host.
  void mask(Rng& rng, std::vector<float>& multiplier, bool compensate) {
    dropout_mask_of(backend_, n_, n_ > 0 ? probabilities_.data() : nullptr, 0.0, compensate, rng, multiplier);
  }

private:
  Backend& backend_;
  std::size_t n_ = 0;
  typename Backend::template Array<float> means_, density_, depth_, probabilities_;
  typename Backend::template Array<std::uint64_t> keys_, keys_sorted_;
  typename Backend::template Array<std::int32_t> index_, index_sorted_;
};

}  // namespace d2gs::train_kernels
