#pragma once
// Adam, one parameter group per attribute as the 3DGS code (method.md §2): betas (0.9, 0.999),
// eps 1e-15, dense updates (every Gaussian every step, zero gradient or not), bias correction with one
// step count shared by all rows (torch keeps `step` per tensor; rows appended by densification start
// with zero moments but share the count). Moments have the model's shape, so densification edits them
// with the same row functions (model/rows.hpp).
#include <algorithm>
#include <cmath>

#include "d2gs/model/gaussians.hpp"

namespace d2gs {

struct LearningRates {
  float means = 1.6e-4f;      // times the scene extent; scheduled by position_lr()
  float sh_dc = 0.0025f;
  float sh_rest = 0.000125f;
  float opacity = 0.05f;
  float scales = 0.005f;
  float quats = 0.001f;
};

// 3DGS's exponential position schedule: log-linear from `initial` to `final` over `max_steps`.
inline double position_lr(double initial, double final_lr, int step, int max_steps) {
  const double t = max_steps > 0 ? std::clamp(static_cast<double>(step) / max_steps, 0.0, 1.0) : 1.0;
  return std::exp(std::log(initial) * (1.0 - t) + std::log(final_lr) * t);
}

struct AdamState {
  Gaussians exp_avg;     // first moments, model-shaped
  Gaussians exp_avg_sq;  // second moments
  long step = 0;
};

class Adam {
public:
  static constexpr double kBeta1 = 0.9, kBeta2 = 0.999, kEps = 1e-15;
  // Zero moments shaped like `model`.
  static AdamState make_state(const Gaussians& model);
  // One step with the given gradients; `means_lr` is the (scheduled) position learning rate.
  // `skip_opacity`: leave opacity and its moments as they are (the original takes no opacity step in
  // the iteration whose opacity reset replaced the tensor).
  static void step(Gaussians& model, const Gaussians& grads, AdamState& state, const LearningRates& lr,
                   float means_lr, bool skip_opacity = false);
};

}  // namespace d2gs
