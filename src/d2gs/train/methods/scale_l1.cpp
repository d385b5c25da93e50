// Regulariser scale-l1: an L1 penalty on the Gaussians' (activated) scales, 3D Gaussian Splatting as Markov
// Chain Monte Carlo's scale regulariser (Kheradmand et al., NeurIPS 2024),
//   L = λ · mean_{i,k} exp(s_ik)   over the N×3 log-scales s,   λ = --scale-l1-lambda (0.01 there),
// on the log-scales directly (no render involved): ∂L/∂s_ik = λ · exp(s_ik) / (3N).
//
// Why: 3DGS-MCMC pairs it with an L1 pull on the opacities, which, like opacity decay, lets fewer Gaussians
// cover the scene, and those grow. On fern, decay's models have half again the median size of DropGaussian's
// and twice its 90th percentile (docs/benchmarks.md, issue 25); the released IMR's covariance term grows with
// the fourth power of a Gaussian's size. The penalty's gradient grows with the size itself, so it acts on the
// largest Gaussians and leaves the small ones to the photometric loss.
#include <cmath>
#include <cstddef>

#include "d2gs/train/methods/method.hpp"

namespace d2gs {
namespace {

class ScaleL1 final : public TrainingMethod {
public:
  explicit ScaleL1(const TrainConfig& c) : lambda_(c.scale_l1_lambda) {}
  const char* name() const override { return "scale-l1"; }

  std::vector<LossTerm> parameter_terms(int /*iteration*/, const Gaussians& model, Gaussians& grad) override {
    const std::size_t count = model.log_scales.size();
    if (count == 0) return {{"scale_l1", 0.0, lambda_}};
    const double per_entry = lambda_ / static_cast<double>(count);
    double sum = 0.0;
    for (std::size_t k = 0; k < count; ++k) {
      const double s = std::exp(static_cast<double>(model.log_scales[k]));
      sum += s;
      grad.log_scales[k] += static_cast<float>(per_entry * s);
    }
    return {{"scale_l1", sum / static_cast<double>(count), lambda_}};
  }

private:
  double lambda_;
};

}  // namespace

std::unique_ptr<TrainingMethod> make_scale_l1(const TrainConfig& config) {
  return std::make_unique<ScaleL1>(config);
}

}  // namespace d2gs
