// Regulariser stereo-depth: the render's disparity pulled towards the multi-view stereo depth of each
// training view (train/losses.hpp, disparity_l1_loss), weighted by --stereo-depth-lambda.
//
// Why: with three views, photometric losses leave depth nearly free (a floater in front of a training
// camera costs nothing in that view); sparse-view NeRF and 3DGS methods fix it with depth from sparse SfM
// points (DS-NeRF) or from monocular networks (DNGaussian, FSGS). Here the depth comes from the training
// views themselves and no network: the PatchMatch depth maps that `d2gs init` computes for the initial
// cloud (geometry/training_geometry.hpp, DIR/depth/NAME.npy), kept only where they passed the
// cross-view consistency filter (0 elsewhere: no target). Disparity rather than depth, so that the far
// background, where stereo is least certain, weighs least.
#include <filesystem>
#include <memory>
#include <vector>

#include "d2gs/core/error.hpp"
#include "d2gs/train/losses.hpp"
#include "d2gs/train/methods/method.hpp"
#include "d2gs/train/view_map.hpp"

namespace d2gs {
namespace {
namespace fs = std::filesystem;

// Pixels whose rendered alpha is below this have no reliable depth (the same cut as D²GS's self-prior).
constexpr double kMinAlpha = 0.5;

class StereoDepth final : public TrainingMethod {
public:
  explicit StereoDepth(const TrainConfig& c) : lambda_(static_cast<float>(c.stereo_depth_lambda)) {}
  const char* name() const override { return "stereo-depth"; }
  bool uses_depth() const override { return true; }

  void start(TrainConfig& /*config*/, const MethodRun& run,
             const std::function<CachedTrainingGeometry()>& training_geometry) override {
    const fs::path dir = training_geometry().depth_dir;
    if (dir.empty()) fail("--regularisers stereo-depth: the training views' geometry has no depth maps");
    targets_.assign(run.split.train.size(), {});
    for (std::size_t k = 0; k < run.split.train.size(); ++k) {
      const Camera& cam = run.scene.cameras[static_cast<std::size_t>(run.split.train[k])];
      // The maps are at the scene folder's highest resolution; pixels without a depth (0) are never
      // averaged into the valid ones.
      Image depth = read_view_map(dir, cam, {.what = "stereo depth", .shape = "depth map", .zero_is_none = true,
                                             .check_depths = true});
      targets_[k] = std::move(depth.pixels);
    }
  }

  std::vector<LossTerm> loss_terms(const MethodLoss& loss) override {
    const auto& target = targets_.at(static_cast<std::size_t>(loss.step.view));
    const std::size_t pixels = static_cast<std::size_t>(loss.width) * static_cast<std::size_t>(loss.height);
    if (target.size() != pixels)
      fail("stereo-depth: the depth target of training view {} has {} pixels, the render {}", loss.step.view,
           target.size(), pixels);
    const double value = disparity_l1_loss(loss.depth, loss.alpha, target.data(), pixels, kMinAlpha, loss.grad_depth,
                                           loss.grad_alpha, lambda_);
    return {{"stereo_depth", value, lambda_}};
  }

private:
  float lambda_;
  std::vector<std::vector<float>> targets_;  // per training view: H×W stereo depth at its size, 0 = none
};

}  // namespace

std::unique_ptr<TrainingMethod> make_stereo_depth(const TrainConfig& config) {
  return std::make_unique<StereoDepth>(config);
}

}  // namespace d2gs
