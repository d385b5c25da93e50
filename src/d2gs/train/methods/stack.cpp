// A method with regularisers stacked on it (--regularisers, registry.cpp): every hook of the method, then
// the same hook of each regulariser in order. Opacity multipliers multiply, loss terms are all kept, and
// a regulariser's checkpoint state is kept under "NAME/GROUP" so that the method's own state keeps its
// plain names (a checkpoint of the method alone reads the same).
#include <string>
#include <utility>
#include <vector>

#include "d2gs/core/error.hpp"
#include "d2gs/train/methods/method.hpp"

namespace d2gs {
namespace {

using Part = std::pair<std::string, std::unique_ptr<TrainingMethod>>;

class Stack final : public TrainingMethod {
public:
  Stack(std::unique_ptr<TrainingMethod> method, std::vector<Part> parts)
      : method_(std::move(method)), parts_(std::move(parts)) {}
  const char* name() const override { return method_->name(); }

  void describe(TrainConfig& as_trained, const MethodRun& run) const override {
    method_->describe(as_trained, run);
    for (const auto& [n, p] : parts_) p->describe(as_trained, run);
  }

  void check_state(const MethodState& state, const RunIdentity& run, std::size_t gaussians) const override {
    std::vector<MethodState> split = split_state(state);
    method_->check_state(split.front(), run, gaussians);
    for (std::size_t k = 0; k < parts_.size(); ++k) {
      try {
        parts_[k].second->check_state(split[k + 1], run, gaussians);
      } catch (const Error& e) {
        fail("regulariser {}: {}", parts_[k].first, e.what());
      }
    }
  }

  void start(TrainConfig& config, const MethodRun& run,
             const std::function<CachedTrainingGeometry()>& training_geometry) override {
    method_->start(config, run, training_geometry);
    for (auto& [n, p] : parts_) p->start(config, run, training_geometry);
  }

  void prepare(const MethodStep& step) override {
    method_->prepare(step);
    for (auto& [n, p] : parts_) p->prepare(step);
  }

  OpacityMultiplier opacity_multiplier(const MethodStep& step) override {
    OpacityMultiplier result = method_->opacity_multiplier(step);
    bool owned = false;  // whether result.values is product_
    for (auto& [n, p] : parts_) {
      const OpacityMultiplier m = p->opacity_multiplier(step);
      if (!m.values) continue;
      if (!result.values) {
        result = m;
        continue;
      }
      const std::size_t count = step.model.size();
      if (!owned) product_.assign(result.values, result.values + count);
      for (std::size_t i = 0; i < count; ++i) product_[i] *= m.values[i];
      owned = true;
      result.values = product_.data();
    }
    if (owned) result.drop_fraction = drop_fraction(product_);
    return result;
  }

  std::vector<LossTerm> loss_terms(const MethodLoss& loss) override {
    std::vector<LossTerm> terms = method_->loss_terms(loss);
    for (auto& [n, p] : parts_)
      for (LossTerm& t : p->loss_terms(loss)) terms.push_back(std::move(t));
    return terms;
  }

  std::vector<LossTerm> parameter_terms(int iteration, const Gaussians& model, Gaussians& grad) override {
    std::vector<LossTerm> terms = method_->parameter_terms(iteration, model, grad);
    for (auto& [n, p] : parts_)
      for (LossTerm& t : p->parameter_terms(iteration, model, grad)) terms.push_back(std::move(t));
    return terms;
  }

  bool uses_depth() const override {
    if (method_->uses_depth()) return true;
    for (const auto& p : parts_)
      if (p.second->uses_depth()) return true;
    return false;
  }

  void before_update(int iteration, Gaussians& model) override {
    method_->before_update(iteration, model);
    for (auto& [n, p] : parts_) p->before_update(iteration, model);
  }

  void after_densify(const DensifyReport& report) override {
    method_->after_densify(report);
    for (auto& [n, p] : parts_) p->after_densify(report);
  }

  MethodState state() const override {
    MethodState s = method_->state();
    for (const auto& [n, p] : parts_) {
      MethodState own = p->state();
      for (auto& [group, arrays] : own.floats) s.floats[n + "/" + group] = std::move(arrays);
      for (auto& [group, arrays] : own.bytes) s.bytes[n + "/" + group] = std::move(arrays);
    }
    return s;
  }

  void restore(MethodState&& state) override {
    std::vector<MethodState> split = split_state(state);
    method_->restore(std::move(split.front()));
    for (std::size_t k = 0; k < parts_.size(); ++k) parts_[k].second->restore(std::move(split[k + 1]));
  }

private:
  // The method's state (first), then each regulariser's, its "NAME/" taken off.
  std::vector<MethodState> split_state(const MethodState& state) const {
    std::vector<MethodState> split(parts_.size() + 1);
    const auto owner = [&](const std::string& group) -> std::pair<std::size_t, std::string> {
      for (std::size_t k = 0; k < parts_.size(); ++k) {
        const std::string prefix = parts_[k].first + "/";
        if (group.rfind(prefix, 0) == 0) return {k + 1, group.substr(prefix.size())};
      }
      return {0, group};
    };
    for (const auto& [group, arrays] : state.floats) {
      const auto [k, name] = owner(group);
      split[k].floats[name] = arrays;
    }
    for (const auto& [group, arrays] : state.bytes) {
      const auto [k, name] = owner(group);
      split[k].bytes[name] = arrays;
    }
    return split;
  }

  std::unique_ptr<TrainingMethod> method_;
  std::vector<Part> parts_;
  std::vector<float> product_;  // the product of several multipliers
};

}  // namespace

std::unique_ptr<TrainingMethod> stack_methods(std::unique_ptr<TrainingMethod> method, std::vector<Part> parts) {
  return std::make_unique<Stack>(std::move(method), std::move(parts));
}

}  // namespace d2gs
