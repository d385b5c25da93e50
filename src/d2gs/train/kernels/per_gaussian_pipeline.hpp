#pragma once
// The host side of the dropout-mask and densification-statistic kernels over a backend of
// render/kernels/pipeline.hpp, written once (CI runs it through the emulator). Host arrays in and out.
#include <algorithm>
#include <array>
#include <cstdint>
#include <utility>
#include <vector>

#include "d2gs/core/error.hpp"
#include "d2gs/core/random.hpp"
#include "d2gs/render/kernels/block.hpp"
#include "d2gs/train/densify.hpp"
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

// dropgaussian_mask (probabilities null) or bernoulli_mask: the same multipliers from the same draws, and
// rng left where the CPU leaves it (n draws on).
template <class Backend>
void dropout_mask(Backend& backend, std::size_t n, const float* probabilities, double rate, bool compensate, Rng& rng,
                  std::vector<float>& multiplier) {
  multiplier.resize(n);
  if (n == 0) return;
  const long long chunks = (static_cast<long long>(n) + kDrawsPerThread - 1) / kDrawsPerThread;
  if (n > static_cast<std::size_t>(1u << 31) - 1 || chunks >= (1LL << kJumpBits))
    fail("dropout kernel: {} Gaussians exceed the int32 indices", n);
  typename Backend::template Array<uint64_t> jumps, end_state;
  typename Backend::template Array<float> p, out;
  const auto& table = dropout_jump_table();
  backend.upload(jumps, table.data(), table.size());
  end_state.resize(4);
  out.resize(n);
  DropoutMaskArgs a;
  a.n = static_cast<int>(chunks);
  a.count = static_cast<int>(n);
  const Rng::State before = rng.state();
  for (int k = 0; k < 4; ++k) a.state[k] = before.words[k];
  a.jumps = jumps.data();
  if (probabilities) {
    backend.upload(p, probabilities, n);
    a.probabilities = p.data();
    a.compensate = compensate;
  } else {
    a.rate = rate;
    a.keep_scale = static_cast<float>(1.0 / (1.0 - rate));
  }
  a.multiplier = out.data();
  a.end_state = end_state.data();
  backend.template launch<DropoutMaskKernel>(render::kernels::blocks_for(chunks), render::kernels::kBlockThreads, a);
  backend.download(multiplier, out, n);
  std::vector<uint64_t> after;
  backend.download(after, end_state, 4);
  Rng::State state = before;
  for (int k = 0; k < 4; ++k) state.words[k] = after[static_cast<std::size_t>(k)];
  rng.set_state(state);
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
  backend.template launch<GradientStatsKernel>(render::kernels::blocks_for(static_cast<long long>(n)),
                                               render::kernels::kBlockThreads, a);
  std::vector<float> sums, counts;
  backend.download(sums, sum, n);
  backend.download(counts, count, n);
  stats.restore(std::move(sums), std::move(counts));
}

}  // namespace d2gs::train_kernels
