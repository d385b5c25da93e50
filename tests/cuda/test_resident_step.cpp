// The device-resident training step (train/kernels/device_step.hpp, resident_step.hpp). Each of its kernels
// is checked on its own elsewhere (the stages and compositing against the CPU rasterizer, the L1, SSIM,
// dropout, statistic and Adam kernels against the CPU's functions); here the chaining is checked: the
// emulated resident step must give, bit for bit, what the same kernels give when called one by one with host
// arrays in between, as `train --device emulated` chains them (the kernel rasterizer, emulated_l1_loss,
// emulated_ssim, emulated_dropgaussian_mask, emulated_add_gradient_stats, emulated_adam_step), over several
// steps, two views, DropGaussian's mask and a densification done on the host between two uploads. On a GPU
// (skipped without one) the device's step must follow the emulated one within float tolerance.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include <glm/gtc/quaternion.hpp>

#include "cuda/stage_compare.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/random.hpp"
#include "d2gs/eval/ssim.hpp"
#include "d2gs/render/cuda/device.hpp"
#include "d2gs/render/kernels/kernel_rasterizer.hpp"
#include "d2gs/render/raster_math.hpp"
#include "d2gs/train/densify.hpp"
#include "d2gs/train/dropout.hpp"
#include "d2gs/train/methods/method.hpp"
#include "d2gs/train/kernels/device_step.hpp"
#include "d2gs/train/kernels/optim.hpp"
#include "d2gs/train/loss_math.hpp"
#include "d2gs/train/losses.hpp"
#include "d2gs/scene/camera.hpp"
#include "test_errors.hpp"

namespace d2gs::test {
namespace {

namespace tk = train_kernels;

// Two 64x48 views of one random model (SH degree 3), random target images.
struct StepScene {
  Gaussians model;
  std::vector<render::RenderCamera> cameras;
  std::vector<Image> images;
  std::vector<Ssim<float>::Reference> refs;
};

StepScene step_scene() {
  StepScene s;
  s.cameras = {test_camera<float>(64, 48, 21), test_camera<float>(64, 48, 22)};
  const TestModel<float> m = random_model<float>(s.cameras[0], 500, 23, 0.9);
  s.model.resize(m.size(), m.sh_degree);
  s.model.means = m.means;
  s.model.log_scales = m.log_scales;
  s.model.quats = m.quats;
  s.model.opacity_logits = m.opacity_logits;
  s.model.sh_dc = m.sh_dc;
  s.model.sh_rest = m.sh_rest;
  // Bright enough that some pixels exceed 1, so the clamp and its gradient rule are exercised.
  for (std::size_t i = 0; i < 3 * 100; ++i) s.model.sh_dc[i] = 4.0f * std::abs(s.model.sh_dc[i]) + 2.0f;
  std::mt19937 rng(24);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  Ssim<float> ssim;
  for (const auto& cam : s.cameras) {
    Image im;
    im.width = cam.width;
    im.height = cam.height;
    im.channels = 3;
    im.pixels.resize(static_cast<std::size_t>(cam.width) * cam.height * 3);
    for (float& v : im.pixels) v = u(rng);
    s.refs.push_back(ssim.reference(im.pixels.data(), im.width, im.height, 3));
    s.images.push_back(std::move(im));
  }
  return s;
}

struct Schedule {
  int steps = 5;
  int densify_after = 2;  // densify on the host after this step's statistic (0: never)
  bool dropgaussian = true;
  double drop_rate = 0.1;
  float lambda_dssim = 0.2f;
  bool d2gs = false;  // DD-Drop's multiplier (instead of DropGaussian's) and the DAFE term
};

// D²GS's inputs: a camera for the depths, density scores for n Gaussians (new ones after a densification),
// a far-region mask per view.
Camera dd_camera() {
  Camera cam;
  cam.width = 64;
  cam.height = 48;
  cam.R_world_to_cam = glm::mat3_cast(glm::normalize(glm::dquat(0.9, 0.1, -0.2, 0.3)));
  cam.t_world_to_cam = glm::dvec3(0.1, -0.2, 3.0);
  return cam;
}
std::vector<float> density_scores_for(std::size_t n) {
  std::mt19937 rng(static_cast<unsigned>(n));
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<float> d(n);
  for (float& v : d) v = u(rng);
  return d;
}
std::vector<std::vector<std::uint8_t>> far_masks() {
  std::mt19937 rng(31);
  std::vector<std::vector<std::uint8_t>> masks(2, std::vector<std::uint8_t>(64 * 48));
  for (auto& m : masks)
    for (auto& v : m) v = rng() % 3 == 0;
  return masks;
}
DdDropOptions dd_options() {
  DdDropOptions o;
  o.compensate = true;
  return o;
}
constexpr float kDafeWeight = 0.5f;

tk::ResidentRender render_of(const render::RenderCamera& cam, int active_degree, const Schedule& sc) {
  tk::ResidentRender r;
  r.camera = cam;
  r.stages.active_degree = active_degree;
  r.stages.alpha_min = render::kAlphaMin;
  r.composite.background[0] = 0.1f;
  r.composite.background[1] = 0.2f;
  r.composite.background[2] = 0.3f;
  r.composite.fused_multiply_add = true;
  r.dropgaussian = sc.dropgaussian;
  r.drop_rate = sc.drop_rate;
  return r;
}

DensifyOptions densify_options() {
  DensifyOptions o;
  o.grad_threshold = 1e-6f;  // small: some Gaussians clone and split after a few steps
  return o;
}

struct Trajectory {
  Gaussians model;
  AdamState adam;
  GradientStats stats;
  std::vector<double> l1, ssim, drop_fraction, dafe;
  Rng dropout = Rng::stream(7, "dropout"), densify = Rng::stream(7, "densify");
};

Trajectory start(const StepScene& s) {
  Trajectory t;
  t.model = s.model;
  t.adam = Adam::make_state(t.model);
  t.stats.reset(t.model.size());
  return t;
}

// The kernels called one by one, host arrays in between: the hybrid step of `train --device emulated`.
Trajectory one_by_one(const StepScene& s, const Schedule& sc) {
  Trajectory t = start(s);
  auto raster = render::kernels::make_kernel_rasterizer(render::kernels::make_emulated_stages(), true);
  const LearningRates lr;
  for (int k = 1; k <= sc.steps; ++k) {
    const std::size_t view = static_cast<std::size_t>(k % 2);
    const tk::ResidentRender r = render_of(s.cameras[view], std::min(k / 2, 3), sc);
    std::vector<float> mult;
    if (sc.dropgaussian) tk::emulated_dropgaussian_mask(t.model.size(), sc.drop_rate, t.dropout, mult);
    if (sc.d2gs)
      tk::emulated_dd_drop_mask(t.model, dd_camera(), density_scores_for(t.model.size()), dd_options(), k, t.dropout,
                                mult);
    const bool multiplied = sc.dropgaussian || sc.d2gs;
    t.drop_fraction.push_back(multiplied ? drop_fraction(mult) : 0.0);
    render::RenderOptions ro;
    ro.background = {r.composite.background[0], r.composite.background[1], r.composite.background[2]};
    ro.sh_degree = r.stages.active_degree;
    const auto& out = raster->forward(t.model, multiplied ? mult.data() : nullptr, r.camera, ro);
    std::vector<float> pred(out.rgb.size()), grad(out.rgb.size(), 0.0f);
    for (std::size_t i = 0; i < pred.size(); ++i) pred[i] = clamp_unit(out.rgb[i]);
    t.l1.push_back(tk::emulated_l1_loss(pred.data(), s.images[view].pixels.data(), pred.size(), grad.data(), 1.0f));
    t.ssim.push_back(tk::emulated_ssim(pred.data(), s.refs[view], grad.data(), -sc.lambda_dssim));
    if (sc.d2gs)
      t.dafe.push_back(tk::emulated_dafe_loss(pred.data(), s.images[view].pixels.data(), 64, 48, 3, far_masks()[view],
                                              DafeLossForm::Paper, grad.data(), kDafeWeight));
    for (std::size_t i = 0; i < pred.size(); ++i)
      if (clamp_blocks_gradient(out.rgb[i])) grad[i] = 0.0f;
    const auto radii = out.radii;
    const auto& g = raster->backward(grad.data(), nullptr, nullptr);
    tk::emulated_add_gradient_stats(t.stats, g.grad_mean2d_ndc, radii);
    bool skip = false;
    if (k == sc.densify_after) {
      densify_and_prune(t.model, t.adam, t.stats, 1.0f, densify_options(), t.densify);
      skip = true;
    }
    if (!skip) tk::emulated_adam_step(t.model, g.model, t.adam, lr, 1e-3f, k == 3);
  }
  return t;
}

// The resident step, the model downloaded only to densify and at the end.
Trajectory resident(tk::DeviceStep& step, const StepScene& s, const Schedule& sc) {
  Trajectory t = start(s);
  step.set_training_views(s.images, s.refs);
  step.upload(t.model, t.adam, t.stats);
  const LearningRates lr;
  const auto masks = far_masks();
  for (int k = 1; k <= sc.steps; ++k) {
    const std::size_t view = static_cast<std::size_t>(k % 2);
    tk::ResidentRender r = render_of(s.cameras[view], std::min(k / 2, 3), sc);
    const std::vector<float> density = density_scores_for(t.model.size());
    tk::ResidentDdDrop dd;
    tk::ResidentDafe dafe;
    if (sc.d2gs) {
      dd.options = dd_options();
      dd.camera = dd_camera();
      dd.iteration = k;
      dd.density = &density;
      dd.density_version = t.model.size();  // new scores with every new size
      r.dd_drop = &dd;
      dafe.mask = &masks[view];
      dafe.mask_version = 1;
      dafe.form = DafeLossForm::Paper;
      dafe.weight = kDafeWeight;
      r.dafe = &dafe;
    }
    const tk::ResidentLoss loss = step.render_and_backward(view, r, t.dropout, sc.lambda_dssim);
    if (sc.d2gs) t.dafe.push_back(loss.dafe);
    t.l1.push_back(loss.l1);
    t.ssim.push_back(loss.ssim);
    t.drop_fraction.push_back(loss.drop_fraction);
    EXPECT_TRUE(step.gradients_finite()) << "step " << k;
    step.add_gradient_stats();
    if (k == sc.densify_after) {
      step.download(t.model, t.adam, t.stats);
      densify_and_prune(t.model, t.adam, t.stats, 1.0f, densify_options(), t.densify);
      step.upload(t.model, t.adam, t.stats);
      continue;
    }
    step.adam(lr, 1e-3f, k == 3);
    EXPECT_TRUE(step.parameters_finite()) << "step " << k;
  }
  step.download(t.model, t.adam, t.stats);
  return t;
}

void expect_resident_equals_one_by_one(const Schedule& sc) {
  const StepScene s = step_scene();
  const Trajectory want = one_by_one(s, sc);
  auto step = tk::make_emulated_step();
  const Trajectory got = resident(*step, s, sc);
  ASSERT_GT(want.model.size(), s.model.size()) << "the densification should have added Gaussians";
  {  // the scene exercises the clamp: some pixel of the first render lies above 1
    auto raster = render::kernels::make_kernel_rasterizer(render::kernels::make_emulated_stages(), true);
    render::RenderOptions ro;
    const auto& out = raster->forward(s.model, nullptr, s.cameras[1], ro);
    int above = 0;
    for (float v : out.rgb) above += v > 1.0f;
    ASSERT_GT(above, 0);
  }
  expect_bit_equal(got.model, want.model, "model");
  expect_bit_equal(got.adam.exp_avg, want.adam.exp_avg, "first moments");
  expect_bit_equal(got.adam.exp_avg_sq, want.adam.exp_avg_sq, "second moments");
  EXPECT_EQ(got.adam.step, want.adam.step);
  EXPECT_TRUE(bit_equal(got.stats.sums(), want.stats.sums()));
  EXPECT_TRUE(bit_equal(got.stats.counts(), want.stats.counts()));
  EXPECT_EQ(got.l1, want.l1);
  EXPECT_EQ(got.ssim, want.ssim);
  EXPECT_EQ(got.drop_fraction, want.drop_fraction);
  EXPECT_GT(got.drop_fraction[0], 0.0);
  EXPECT_EQ(got.dafe, want.dafe);
  for (int w = 0; w < 4; ++w) EXPECT_EQ(got.dropout.state().words[w], want.dropout.state().words[w]);
}

TEST(ResidentStep, EmulatedEqualsTheKernelsCalledOneByOne) { expect_resident_equals_one_by_one(Schedule{}); }

// D²GS's step: DD-Drop's probabilities from the means on the device and the density scores (uploaded again
// when a densification changed the model's size), its mask, and the DAFE term on each view's mask.
TEST(ResidentStep, EmulatedD2gsEqualsTheKernelsCalledOneByOne) {
  Schedule sc;
  sc.dropgaussian = false;
  sc.d2gs = true;
  expect_resident_equals_one_by_one(sc);
}

TEST(ResidentStep, OneStepMovesEveryParameterGroup) {
  const StepScene s = step_scene();
  Schedule sc;
  sc.steps = 1;
  sc.densify_after = 0;
  auto step = tk::make_emulated_step();
  const Trajectory got = resident(*step, s, sc);
  ASSERT_EQ(got.model.size(), s.model.size());
  EXPECT_FALSE(bit_equal(got.model.means, s.model.means));
  EXPECT_FALSE(bit_equal(got.model.log_scales, s.model.log_scales));
  EXPECT_FALSE(bit_equal(got.model.quats, s.model.quats));
  EXPECT_FALSE(bit_equal(got.model.opacity_logits, s.model.opacity_logits));
  EXPECT_FALSE(bit_equal(got.model.sh_dc, s.model.sh_dc));
  EXPECT_EQ(got.adam.step, 1);
  double visible = 0;
  for (float c : got.stats.counts()) visible += c;
  EXPECT_GT(visible, 0.0);
  EXPECT_GT(got.l1[0], 0.0);
  EXPECT_LT(got.ssim[0], 1.0);
}

TEST(ResidentStep, RejectsMismatchedInputs) {
  const StepScene s = step_scene();
  auto step = tk::make_emulated_step();
  std::vector<Ssim<float>::Reference> one_ref(s.refs.begin(), s.refs.begin() + 1);
  EXPECT_THROW(step->set_training_views(s.images, one_ref), Error);
  step->set_training_views(s.images, s.refs);
  Trajectory t = start(s);
  t.stats.reset(3);
  EXPECT_THROW(step->upload(t.model, t.adam, t.stats), Error);
  t.stats.reset(t.model.size());
  step->upload(t.model, t.adam, t.stats);
  const Schedule sc;
  EXPECT_THROW(step->render_and_backward(2, render_of(s.cameras[0], 0, sc), t.dropout, 0.2f), Error);
  tk::ResidentRender wrong = render_of(test_camera<float>(32, 24, 5), 0, sc);
  EXPECT_THROW(step->render_and_backward(0, wrong, t.dropout, 0.2f), Error);
  tk::ResidentRender bad_rate = render_of(s.cameras[0], 0, sc);
  bad_rate.drop_rate = 1.0;
  EXPECT_THROW(step->render_and_backward(0, bad_rate, t.dropout, 0.2f), Error);
}

TEST(ResidentStep, DeviceFollowsTheEmulator) {
  if (cuda::device_count() == 0) GTEST_SKIP() << cuda::describe_device();
  const StepScene s = step_scene();
  const Schedule sc;
  auto emulated = tk::make_emulated_step();
  auto device = tk::make_device_step();
  const Trajectory want = resident(*emulated, s, sc);
  const Trajectory got = resident(*device, s, sc);
  // The GPU's expf and atomics differ from the emulator's in the last bits; a densification can then choose
  // otherwise for a Gaussian at its threshold, so the sizes must agree and the values be close.
  ASSERT_EQ(got.model.size(), want.model.size());
  EXPECT_LT(closeness(got.model.means, want.model.means, want.model.means.size()).rel_l2, 1e-4);
  EXPECT_LT(closeness(got.model.opacity_logits, want.model.opacity_logits, want.model.size()).rel_l2, 1e-3);
  EXPECT_LT(closeness(got.model.sh_dc, want.model.sh_dc, want.model.sh_dc.size()).rel_l2, 1e-3);
  for (std::size_t k = 0; k < want.l1.size(); ++k) {
    EXPECT_NEAR(got.l1[k], want.l1[k], 1e-5 * want.l1[k]) << "step " << k + 1;
    EXPECT_NEAR(got.ssim[k], want.ssim[k], 1e-5) << "step " << k + 1;
  }
}

}  // namespace
}  // namespace d2gs::test
