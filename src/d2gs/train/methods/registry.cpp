// The training methods, by name: the one place a method is registered. A new method: its file in this
// folder (a TrainingMethod and its make_ function), the make_ function declared and listed below, and
// its source in src/d2gs/train/CMakeLists.txt.
#include <algorithm>
#include <utility>

#include <fmt/format.h>

#include "d2gs/core/error.hpp"
#include "d2gs/train/methods/method.hpp"

namespace d2gs {

std::unique_ptr<TrainingMethod> make_gs3d(const TrainConfig& config);
std::unique_ptr<TrainingMethod> make_dropgaussian(const TrainConfig& config);
std::unique_ptr<TrainingMethod> make_d2gs(const TrainConfig& config);
std::unique_ptr<TrainingMethod> make_opacity_noise(const TrainConfig& config);
std::unique_ptr<TrainingMethod> make_opacity_decay(const TrainConfig& config);
std::unique_ptr<TrainingMethod> make_stereo_depth(const TrainConfig& config);
std::unique_ptr<TrainingMethod> make_anisotropy(const TrainConfig& config);
std::unique_ptr<TrainingMethod> make_scale_l1(const TrainConfig& config);
std::unique_ptr<TrainingMethod> stack_methods(std::unique_ptr<TrainingMethod> method,
                                              std::vector<std::pair<std::string, std::unique_ptr<TrainingMethod>>> parts);

const std::vector<MethodInfo>& training_methods() {
  static const std::vector<MethodInfo> methods = {
      {"3dgs", "3D Gaussian Splatting (no dropout)", &make_gs3d},
      {"dropgaussian", "DropGaussian: uniform dropout with opacity compensation", &make_dropgaussian},
      {"d2gs", "D²GS: depth-and-density dropout (DD-Drop) and distance-aware fidelity enhancement (DAFE)", &make_d2gs},
  };
  return methods;
}

const std::vector<MethodInfo>& training_regularisers() {
  static const std::vector<MethodInfo> regularisers = {
      {"opacity-noise", "training renders with each opacity times 1 + ε, ε ~ N(0, σ²) clipped to [−σ, σ] (Co-Adaptation of 3DGS)",
       &make_opacity_noise},
      {"opacity-decay", "each opacity times a factor after every iteration past --densify-from (Binocular3DGS)",
       &make_opacity_decay},
      {"stereo-depth", "the render's disparity pulled towards the training views' multi-view stereo depth, weighted by "
                       "--stereo-depth-lambda",
       &make_stereo_depth},
      {"anisotropy", "a hinge on each Gaussian's log axis ratio beyond --anisotropy-ratio, weighted by --anisotropy-lambda "
                     "(PhysGaussian)",
       &make_anisotropy},
      {"scale-l1", "an L1 pull on the Gaussians' scales, mean over the N×3 scales weighted by --scale-l1-lambda (3DGS-MCMC)",
       &make_scale_l1},
  };
  return regularisers;
}

const MethodInfo* find_training_method(const std::string& name) {
  for (const MethodInfo& m : training_methods())
    if (name == m.name) return &m;
  return nullptr;
}

std::string training_method_names() {
  const auto& methods = training_methods();
  std::string names;
  for (std::size_t i = 0; i < methods.size(); ++i)
    names += fmt::format("{}{}", i == 0 ? "" : i + 1 == methods.size() ? " or " : ", ", methods[i].name);
  return names;
}

void check_method_name(const std::string& name) {
  if (!find_training_method(name)) fail("unknown method '{}' (expected {})", name, training_method_names());
}

std::unique_ptr<TrainingMethod> make_training_method(const TrainConfig& config) {
  check_method_name(config.method);
  std::unique_ptr<TrainingMethod> method = find_training_method(config.method)->make(config);
  if (config.regularisers.empty()) return method;
  std::vector<std::pair<std::string, std::unique_ptr<TrainingMethod>>> parts;
  for (const std::string& name : config.regularisers) {
    const auto& all = training_regularisers();
    const auto it = std::find_if(all.begin(), all.end(), [&](const MethodInfo& r) { return name == r.name; });
    if (it == all.end()) fail("unknown regulariser '{}'", name);
    for (const auto& [earlier, part] : parts)
      if (earlier == name) fail("regulariser '{}' is named twice", name);
    parts.emplace_back(name, it->make(config));
  }
  return stack_methods(std::move(method), std::move(parts));
}

void TrainingMethod::check_state(const MethodState& state, const RunIdentity&, std::size_t) const {
  for (const auto& [group, arrays] : state.floats) fail("it holds state '{}', which --method {} does not keep", group, name());
  for (const auto& [group, arrays] : state.bytes) fail("it holds state '{}', which --method {} does not keep", group, name());
}

double drop_fraction(const std::vector<float>& multiplier) {
  if (multiplier.empty()) return 0.0;
  std::size_t dropped = 0;
  for (float m : multiplier) dropped += m == 0.0f;
  return static_cast<double>(dropped) / static_cast<double>(multiplier.size());
}

}  // namespace d2gs
