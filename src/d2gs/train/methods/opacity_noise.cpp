// Regulariser opacity-noise (Co-Adaptation of 3DGS, Chen et al., NeurIPS 2025): every training render
// sees each Gaussian's opacity o times 1 + ε, ε ~ N(0, σ²) clipped to [−σ, σ], the product capped at 1;
// test renders see o. The noise of iteration t comes from its own stream (the seed and t), so it keeps
// no state and a resumed run draws what the uninterrupted one drew.
// One difference from the release's PyTorch: where the cap is active its clamp passes no gradient to o,
// while here the multiplier 1/o does (o·m = 1 exactly, so the forward is the same).
#include <algorithm>
#include <cstdint>

#include "d2gs/render/activations.hpp"
#include "d2gs/train/methods/method.hpp"

namespace d2gs {
namespace {

class OpacityNoise final : public TrainingMethod {
public:
  explicit OpacityNoise(const TrainConfig& c)
      : sigma_(c.opacity_noise_sigma), stream_(Rng::stream(c.seed, "opacity-noise").next_u64()) {}
  const char* name() const override { return "opacity-noise"; }

  OpacityMultiplier opacity_multiplier(const MethodStep& step) override {
    Rng rng(SplitMix64::mix(stream_ ^ static_cast<std::uint64_t>(step.iteration)));
    const std::size_t n = step.model.size();
    multiplier_.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      const double eps = std::clamp(sigma_ * rng.normal(), -sigma_, sigma_);
      const double o = sigmoid(step.model.opacity_logits[i]);
      multiplier_[i] = static_cast<float>(std::min(1.0 + eps, 1.0 / o));
    }
    return {multiplier_.data(), 0.0};
  }

private:
  double sigma_;
  std::uint64_t stream_;  // this run's noise: the seed's "opacity-noise" stream
  std::vector<float> multiplier_;
};

}  // namespace

std::unique_ptr<TrainingMethod> make_opacity_noise(const TrainConfig& config) {
  return std::make_unique<OpacityNoise>(config);
}

}  // namespace d2gs
