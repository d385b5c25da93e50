// Regulariser anisotropy: a hinge on each Gaussian's axis ratio (PhysGaussian, Xie et al., CVPR 2024,
// "anisotropy regularisation"; TLC-Calib and others use the same term),
//   L = mean_i max(0, ln(s_max,i / s_min,i) − ln r),   r = --anisotropy-ratio (10 there),
// weighted by --anisotropy-lambda, on the log-scales directly (no render involved).
//
// Why: with three views, much of the scene is seen from one side only, and the optimiser is free to
// flatten Gaussians into needles and sheets with axis ratios of 10³–10⁶ (fern's trained models; opacity
// decay makes them more extreme, docs/benchmarks.md, issue 25). Needles are what novel views show as
// streaks, and they are what the IMR's covariance term is most sensitive to: ¼·tr((Σa − Σb) Σb⁻¹ (Σa − Σb))
// grows as 1 / (the thin axis of b)².
//
// One difference from PhysGaussian's form, mean_i max(ratio_i, r) − r: the hinge is on the log of the ratio.
// Its gradient on the log-scales is ±1/N for every Gaussian beyond r, whatever the ratio; the ratio form's
// is ±ratio/N, 10⁶ times the photometric gradients for the worst needles, which fills Adam's second moment
// and freezes those Gaussians' scales for thousands of iterations after the ratio has come down.
#include <cmath>
#include <cstddef>

#include "d2gs/train/methods/method.hpp"

namespace d2gs {
namespace {

class Anisotropy final : public TrainingMethod {
public:
  explicit Anisotropy(const TrainConfig& c) : log_ratio_(std::log(c.anisotropy_ratio)), lambda_(c.anisotropy_lambda) {}
  const char* name() const override { return "anisotropy"; }

  std::vector<LossTerm> parameter_terms(int /*iteration*/, const Gaussians& model, Gaussians& grad) override {
    const std::size_t n = model.size();
    if (n == 0) return {{"anisotropy", 0.0, lambda_}};
    const float* s = model.log_scales.data();
    float* g = grad.log_scales.data();
    const float step = static_cast<float>(lambda_ / static_cast<double>(n));
    double sum = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
      const float* si = s + 3 * i;
      int hi = 0, lo = 0;  // the first largest and the first smallest axis
      for (int k = 1; k < 3; ++k) {
        if (si[k] > si[hi]) hi = k;
        if (si[k] < si[lo]) lo = k;
      }
      const double excess = static_cast<double>(si[hi]) - static_cast<double>(si[lo]) - log_ratio_;
      if (excess <= 0.0) continue;
      sum += excess;
      g[3 * i + hi] += step;
      g[3 * i + lo] -= step;
    }
    return {{"anisotropy", sum / static_cast<double>(n), lambda_}};
  }

private:
  double log_ratio_;
  double lambda_;
};

}  // namespace

std::unique_ptr<TrainingMethod> make_anisotropy(const TrainConfig& config) {
  return std::make_unique<Anisotropy>(config);
}

}  // namespace d2gs
