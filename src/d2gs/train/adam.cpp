#include "d2gs/train/adam.hpp"

#include <algorithm>

#include "d2gs/core/error.hpp"
#include "d2gs/model/rows.hpp"

namespace d2gs {
namespace {

// The file is compiled with -fno-math-errno (CMakeLists.txt), so that std::sqrt is the sqrtps instruction
// and this loop vectorises; with errno, GCC called an out-of-line std::sqrt per value (about 35
// instructions each). The values are the same: sqrt is correctly rounded either way.
void update(std::vector<float>& p, const std::vector<float>& g, std::vector<float>& m, std::vector<float>& v,
            double lr, double bias1, double bias2) {
  const float b1 = static_cast<float>(Adam::kBeta1), b2 = static_cast<float>(Adam::kBeta2);
  const float step_size = static_cast<float>(lr / bias1);
  const float inv_sqrt_bias2 = static_cast<float>(1.0 / std::sqrt(bias2));
  const float eps = static_cast<float>(Adam::kEps);
  const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(p.size());
  float* __restrict pp = p.data();
  const float* __restrict gp = g.data();
  float* __restrict mp = m.data();
  float* __restrict vp = v.data();
#pragma omp parallel for simd schedule(static)
  for (std::ptrdiff_t i = 0; i < n; ++i) {
    mp[i] = b1 * mp[i] + (1.0f - b1) * gp[i];
    vp[i] = b2 * vp[i] + (1.0f - b2) * gp[i] * gp[i];
    pp[i] -= step_size * mp[i] / (std::sqrt(vp[i]) * inv_sqrt_bias2 + eps);
  }
}

}  // namespace

AdamState Adam::make_state(const Gaussians& model) {
  AdamState s;
  s.exp_avg = model;
  zero_values(s.exp_avg);
  s.exp_avg_sq = s.exp_avg;
  return s;
}

void Adam::step(Gaussians& model, const Gaussians& grads, AdamState& state, const LearningRates& lr, float means_lr,
                bool skip_opacity) {
  grads.validate();
  if (grads.size() != model.size() || state.exp_avg.size() != model.size() || grads.sh_degree != model.sh_degree)
    fail("Adam: model, gradients and moments are not aligned ({}, {}, {} rows)", model.size(), grads.size(),
         state.exp_avg.size());
  ++state.step;
  const double bias1 = 1.0 - std::pow(kBeta1, static_cast<double>(state.step));
  const double bias2 = 1.0 - std::pow(kBeta2, static_cast<double>(state.step));
  auto& m = state.exp_avg;
  auto& v = state.exp_avg_sq;
  update(model.means, grads.means, m.means, v.means, means_lr, bias1, bias2);
  update(model.sh_dc, grads.sh_dc, m.sh_dc, v.sh_dc, lr.sh_dc, bias1, bias2);
  update(model.sh_rest, grads.sh_rest, m.sh_rest, v.sh_rest, lr.sh_rest, bias1, bias2);
  if (!skip_opacity)
    update(model.opacity_logits, grads.opacity_logits, m.opacity_logits, v.opacity_logits, lr.opacity, bias1, bias2);
  update(model.log_scales, grads.log_scales, m.log_scales, v.log_scales, lr.scales, bias1, bias2);
  update(model.quats, grads.quats, m.quats, v.quats, lr.quats, bias1, bias2);
}

}  // namespace d2gs
