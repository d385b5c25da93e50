// 3D Gaussian Splatting (Kerbl et al. 2023; method.md §2): the loop as it is, no hook.
#include "d2gs/train/methods/method.hpp"

namespace d2gs {
namespace {

class Gs3d final : public TrainingMethod {
public:
  const char* name() const override { return "3dgs"; }
  bool runs_on_device() const override { return true; }  // no hook: no multiplier
};

}  // namespace

std::unique_ptr<TrainingMethod> make_gs3d(const TrainConfig&) { return std::make_unique<Gs3d>(); }

}  // namespace d2gs
