// D²GS (method.md §4, §5): DD-Drop, a dropout whose probabilities follow each Gaussian's depth and
// density (train/dropout.hpp), and DAFE, an L1 term on the far region of each training view
// (train/losses.hpp), its mask from a prior map per view or from the model's own depth at iteration 1000.
// The method keeps the density scores (refreshed every density_refresh_every iterations, carried
// through densification or left out of step as the release does) and the far-region masks, and saves
// both in checkpoints.
#include <algorithm>
#include <filesystem>

#include "d2gs/core/error.hpp"
#include "d2gs/train/dropout.hpp"
#include "d2gs/train/losses.hpp"
#include "d2gs/train/methods/method.hpp"
#include "d2gs/train/view_map.hpp"

namespace d2gs {
namespace {
namespace fs = std::filesystem;

// Without a prior folder the model's own normalised depth, rendered for every training view at this
// iteration (the first of DAFE), is the depth prior.
constexpr int kSelfPriorIteration = 1000;

// The names of the method's state in checkpoints.
constexpr const char* kDensityCache = "density_cache";
constexpr const char* kDafeMasks = "dafe_masks";

class D2gs final : public TrainingMethod {
public:
  explicit D2gs(const TrainConfig& c) : dd_(c.dd_drop), dafe_(c.dafe) {}
  const char* name() const override { return "d2gs"; }

  // "stereo" and the folder it resolves to (which config.json records, with kind depth) are one run,
  // so that `--config MODEL/config.json --resume ...` continues it.
  void describe(TrainConfig& as_trained, const MethodRun& run) const override {
    DafeOptions& d = as_trained.dafe;
    if (!d.prior.empty() && d.prior != "stereo") {
      std::error_code ec;
      for (const fs::path& dir : run.geometry_dirs)
        if (fs::equivalent(d.prior, dir / "depth", ec)) d.prior = "stereo";
    }
    if (d.prior == "stereo") d.prior_kind = PriorKind::Depth;
  }

  void check_state(const MethodState& state, const RunIdentity& run, std::size_t gaussians) const override {
    for (const auto& [group, arrays] : state.floats)
      if (group != kDensityCache || arrays.size() > 1) fail("it holds state '{}' ({} arrays), which --method d2gs does not keep", group, arrays.size());
    // The scores follow the model through densification (one per Gaussian), except with the release's
    // cache, which is out of step by design (any size).
    if (const auto cache = state.floats.find(kDensityCache);
        cache != state.floats.end() && !cache->second.empty() && !cache->second.front().empty() &&
        !dd_.release_density_cache && cache->second.front().size() != gaussians)
      fail("its density cache holds {} scores for a model of {} Gaussians", cache->second.front().size(), gaussians);
    for (const auto& [group, arrays] : state.bytes)
      if (group != kDafeMasks) fail("it holds state '{}', which --method d2gs does not keep", group);
    const auto masks = state.bytes.find(kDafeMasks);
    if (masks == state.bytes.end()) return;
    const std::size_t views = run.train_views.size();
    if (!masks->second.empty() && masks->second.size() != views)
      fail("it holds {} DAFE masks for {} training views", masks->second.size(), views);
    for (std::size_t k = 0; k < masks->second.size(); ++k) {
      const std::size_t pixels = static_cast<std::size_t>(run.train_sizes[k][0]) * static_cast<std::size_t>(run.train_sizes[k][1]);
      if (!masks->second[k].empty() && masks->second[k].size() != pixels)
        fail("its DAFE mask of training view {} has {} pixels, the view {}", run.train_views[k], masks->second[k].size(), pixels);
    }
  }

  void start(TrainConfig& config, const MethodRun& run,
             const std::function<CachedTrainingGeometry()>& training_geometry) override {
    if (dafe_.enabled && dafe_.prior == "stereo") {
      config.dafe.prior = training_geometry().depth_dir.string();
      config.dafe.prior_kind = PriorKind::Depth;
      dafe_.prior = config.dafe.prior;
      dafe_.prior_kind = config.dafe.prior_kind;
    }
    masks_.assign(run.split.train.size(), {});
    if (dafe_.enabled && !dafe_.prior.empty()) load_priors(run);
  }

  void prepare(const MethodStep& step) override {
    if (dafe_.enabled && dafe_.prior.empty() && step.iteration == kSelfPriorIteration) make_self_priors(step);
  }

  OpacityMultiplier opacity_multiplier(const MethodStep& step) override {
    const int t = step.iteration;
    const std::size_t n = step.model.size();
    if (refreshes_density(t)) density_ = density_scores(step.model);
    std::vector<float> out_of_step;
    if (density_.size() != n) out_of_step = out_of_step_scores(n);
    const std::vector<float>& density = density_.size() == n ? density_ : out_of_step;
    probabilities_ = dd_drop_probabilities(gaussian_depths(step.model, step.camera, dd_.depth_mode), density, dd_, t);
    bernoulli_mask(probabilities_, step.rng, multiplier_, dd_.compensate);
    return {multiplier_.data(), drop_fraction(multiplier_)};
  }

  std::vector<LossTerm> loss_terms(const MethodLoss& loss) override {
    if (!dafe_.enabled) return {};
    const auto& mask = masks_[static_cast<std::size_t>(loss.step.view)];
    const double value = mask.empty() ? 0.0
                                      : dafe_loss(loss.prediction, loss.target.pixels.data(), loss.width, loss.height,
                                                  loss.channels, mask, dafe_.loss_form, loss.grad, dafe_.lambda);
    return {{"dafe", value, dafe_.lambda}};
  }

  // The device's step: the same refresh and self-prior on the host model, the probabilities, the mask and
  // DAFE on the device (the scores and masks uploaded when they change).
  bool runs_on_device() const override { return true; }
  bool needs_host_model(int t) const override {
    return refreshes_density(t) || (dafe_.enabled && dafe_.prior.empty() && t == kSelfPriorIteration);
  }
  DeviceStepPlan device_plan(const MethodStep& step) override {
    prepare(step);
    const int t = step.iteration;
    const std::size_t n = step.model.size();
    if (refreshes_density(t)) {
      density_ = density_scores(step.model);
      ++density_version_;
    }
    DeviceStepPlan plan;
    plan.dd_drop = true;
    plan.dd = dd_;
    if (density_.size() == n) {
      plan.density = &density_;
    } else {  // the release's cache out of step (as opacity_multiplier)
      if (out_of_step_version_ != density_version_ || out_of_step_.size() != n) {
        out_of_step_ = out_of_step_scores(n);
        out_of_step_version_ = density_version_;
      }
      plan.density = &out_of_step_;
    }
    plan.density_version = density_version_;
    if (dafe_.enabled) {
      plan.dafe = true;
      plan.dafe_mask = &masks_[static_cast<std::size_t>(step.view)];
      plan.dafe_mask_version = masks_version_;
      plan.dafe_form = dafe_.loss_form;
      plan.dafe_weight = dafe_.lambda;
    }
    return plan;
  }

  void after_densify(const DensifyReport& report) override {
    ++density_version_;  // the model's size changed: the scores (or the out-of-step cache) change with it
    if (dd_.release_density_cache || density_.empty()) return;
    std::vector<float> carried(report.source.size());
    for (std::size_t i = 0; i < carried.size(); ++i) carried[i] = density_[report.source[i]];
    density_ = std::move(carried);
  }

  MethodState state() const override {
    MethodState s;
    s.floats[kDensityCache] = {density_};
    s.bytes[kDafeMasks] = masks_;
    return s;
  }

  void restore(MethodState&& s) override {
    if (const auto it = s.floats.find(kDensityCache); it != s.floats.end() && !it->second.empty())
      density_ = std::move(it->second.front());
    if (const auto it = s.bytes.find(kDafeMasks); it != s.bytes.end() && !it->second.empty()) masks_ = std::move(it->second);
    ++density_version_;
    ++masks_version_;
  }

private:
  // Whether iteration t computes the density scores afresh (on the model before its render).
  bool refreshes_density(int t) const { return t == 1 || t % dd_.density_refresh_every == 0 || density_.empty(); }
  // The cache has the model's size except with the release's cache behaviour, where it is out of step
  // after densification: every score 0.5 when the model grew to n, the first n cached scores when it shrank.
  std::vector<float> out_of_step_scores(std::size_t n) const {
    return density_.size() < n ? std::vector<float>(n, 0.5f)
                               : std::vector<float>(density_.begin(), density_.begin() + static_cast<std::ptrdiff_t>(n));
  }

  void load_priors(const MethodRun& run) {
    ++masks_version_;
    // Depth priors mark pixels without a depth by 0 (d2gs init's stereo depth maps): never far, and
    // never averaged into the valid depths when the map is resized (PatchMatch's maps are at the scene
    // folder's highest resolution).
    const bool depth = dafe_.prior_kind == PriorKind::Depth;
    // The folder itself first: its absence is not one view's missing map.
    std::error_code ec;
    if (!std::filesystem::is_directory(dafe_.prior, ec))
      fail_file(dafe_.prior, "--dafe-prior: {}",
                std::filesystem::exists(dafe_.prior, ec) ? "not a folder (expected the folder of the prior maps)"
                                                         : "no such folder");
    for (std::size_t k = 0; k < run.split.train.size(); ++k) {
      const Camera& cam = run.scene.cameras[static_cast<std::size_t>(run.split.train[k])];
      const Image prior = read_view_map(dafe_.prior, cam, {.what = "DAFE prior", .shape = "map", .zero_is_none = depth});
      std::vector<std::uint8_t> valid(prior.pixels.size(), 1);
      if (depth)
        for (std::size_t i = 0; i < valid.size(); ++i) valid[i] = prior.pixels[i] > 0.0f;
      masks_[k] = dafe_mask(prior.pixels, dafe_.prior_kind, dafe_.mask_rule, dafe_.tau, &valid);
    }
  }

  void make_self_priors(const MethodStep& step) {
    ++masks_version_;
    render::RenderOptions ro;
    ro.background = step.render_options.background;
    ro.sh_degree = step.render_options.sh_degree;
    for (std::size_t k = 0; k < step.train_cameras.size(); ++k) {
      const auto& out = step.rasterizer.forward(step.model, nullptr, step.train_cameras[k], ro);
      std::vector<float> depth(out.depth.size());
      std::vector<std::uint8_t> valid(out.depth.size());
      for (std::size_t i = 0; i < depth.size(); ++i) {
        valid[i] = out.alpha[i] > 0.5f;
        depth[i] = valid[i] ? out.depth[i] / out.alpha[i] : 0.0f;
      }
      masks_[k] = dafe_mask(depth, PriorKind::Depth,
                            dafe_.mask_rule == DafeMaskRule::Threshold ? DafeMaskRule::Threshold : DafeMaskRule::Percentile,
                            dafe_.tau, &valid);
    }
  }

  DdDropOptions dd_;
  DafeOptions dafe_;
  std::vector<float> density_;                    // density scores (out of step with the model in the release mode)
  std::vector<std::vector<std::uint8_t>> masks_;  // far-region mask per training view (empty: none yet)
  std::vector<float> probabilities_, multiplier_;  // per-iteration buffers
  // The device's step: versions of the scores and masks (its uploads follow them), the out-of-step cache.
  std::uint64_t density_version_ = 0, masks_version_ = 0, out_of_step_version_ = ~std::uint64_t{0};
  std::vector<float> out_of_step_;
};

}  // namespace

std::unique_ptr<TrainingMethod> make_d2gs(const TrainConfig& config) { return std::make_unique<D2gs>(config); }

}  // namespace d2gs
