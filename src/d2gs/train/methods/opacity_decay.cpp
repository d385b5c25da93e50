// Regulariser opacity-decay (Binocular3DGS, Han et al., NeurIPS 2024): after every iteration t past
// --densify-from (but the last), each Gaussian's opacity is multiplied by a factor (0.995 there): in logit
// space l ← logit(f·sigmoid(l)); the Adam moments stay. Gaussians whose gradients do not hold their
// opacity up fade below --min-opacity and are pruned. Binocular3DGS uses it instead of the opacity reset
// (--opacity-reset-at none there) and densifies to the end.
#include <cmath>

#include "d2gs/render/activations.hpp"
#include "d2gs/train/methods/method.hpp"

namespace d2gs {
namespace {

class OpacityDecay final : public TrainingMethod {
public:
  explicit OpacityDecay(const TrainConfig& c) : factor_(c.opacity_decay_factor), from_(c.densify_from) {}
  const char* name() const override { return "opacity-decay"; }

  void before_update(int iteration, Gaussians& model) override {
    if (iteration <= from_ || factor_ == 1.0) return;
    const double log_factor = std::log(factor_);
    for (float& l : model.opacity_logits) {
      const double d = factor_ * sigmoid(static_cast<double>(l));
      // logit(f·o); for an opacity that underflows, its limit l + log f.
      l = static_cast<float>(d > 0.0 ? std::log(d) - std::log1p(-d) : l + log_factor);
    }
  }

private:
  double factor_;
  int from_;
};

}  // namespace

std::unique_ptr<TrainingMethod> make_opacity_decay(const TrainConfig& config) {
  return std::make_unique<OpacityDecay>(config);
}

}  // namespace d2gs
