#pragma once
// The training methods by name (registry.cpp): what --method accepts and --help lists, and the one
// place a new method is registered. The interface itself is method.hpp.
#include <memory>
#include <string>
#include <vector>

namespace d2gs {

struct TrainConfig;
class TrainingMethod;

struct MethodInfo {
  const char* name;  // --method
  const char* help;
  std::unique_ptr<TrainingMethod> (*make)(const TrainConfig& config);
};

// Every method, in the order --help lists them.
const std::vector<MethodInfo>& training_methods();
// Every regulariser (--regularisers): components stacked on any method (method.hpp, stack.cpp).
const std::vector<MethodInfo>& training_regularisers();
// The method named `name`; null when there is none.
const MethodInfo* find_training_method(const std::string& name);
// Throws d2gs::Error "unknown method 'NAME' (expected 3dgs, dropgaussian or d2gs)" for a name no method has.
void check_method_name(const std::string& name);
// "3dgs, dropgaussian or d2gs".
std::string training_method_names();
// config.method's method, made from `config`, with config.regularisers stacked on it in their order;
// throws d2gs::Error for a name no method or regulariser has.
std::unique_ptr<TrainingMethod> make_training_method(const TrainConfig& config);

}  // namespace d2gs
