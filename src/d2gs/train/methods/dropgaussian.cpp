// DropGaussian (method.md §4): every Gaussian dropped with probability r = max·t/T, kept ones' opacity
// scaled by 1/(1 − r) (train/dropout.hpp).
#include "d2gs/train/dropout.hpp"
#include "d2gs/train/methods/method.hpp"

namespace d2gs {
namespace {

class DropGaussian final : public TrainingMethod {
public:
  explicit DropGaussian(const TrainConfig& c) : max_rate_(c.dropgaussian_max_rate), iterations_(c.iterations) {}
  const char* name() const override { return "dropgaussian"; }

  OpacityMultiplier opacity_multiplier(const MethodStep& step) override {
    dropgaussian_mask(step.model.size(), dropgaussian_rate(step.iteration, iterations_, max_rate_), step.rng, multiplier_);
    return {multiplier_.data(), drop_fraction(multiplier_)};
  }
  // The same mask drawn on the device from the same stream (train/kernels/dropout_kernels.hpp).
  bool runs_on_device() const override { return true; }
  DeviceStepPlan device_plan(const MethodStep& step) override {
    DeviceStepPlan plan;
    plan.dropgaussian = true;
    plan.rate = dropgaussian_rate(step.iteration, iterations_, max_rate_);
    return plan;
  }

private:
  double max_rate_;
  int iterations_;  // T of the rate schedule: the run's length
  std::vector<float> multiplier_;
};

}  // namespace

std::unique_ptr<TrainingMethod> make_dropgaussian(const TrainConfig& config) {
  return std::make_unique<DropGaussian>(config);
}

}  // namespace d2gs
