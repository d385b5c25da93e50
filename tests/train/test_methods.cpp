// The training methods behind train/methods/method.hpp: the registry, each method's hooks against the
// functions they stand for (train/dropout.hpp, train/losses.hpp), D²GS's density cache through
// densification, and the checks of a checkpoint's method state.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>

#include "d2gs/core/error.hpp"
#include "d2gs/core/npy.hpp"
#include "d2gs/core/random.hpp"
#include "d2gs/render/rasterizer.hpp"
#include "d2gs/train/dropout.hpp"
#include "d2gs/train/losses.hpp"
#include "d2gs/train/methods/method.hpp"
#include "d2gs/train/view_map.hpp"
#include "test_errors.hpp"
#include "test_paths.hpp"

namespace d2gs {
namespace {

Gaussians random_model(std::size_t n) {
  Rng rng(5);
  Gaussians g;
  g.resize(n, 0);
  for (auto* a : {&g.means, &g.log_scales, &g.quats, &g.opacity_logits, &g.sh_dc, &g.sh_rest})
    for (float& v : *a) v = static_cast<float>(rng.normal());
  for (std::size_t i = 0; i < n; ++i) g.means[3 * i + 2] += 5.0f;  // in front of the camera
  return g;
}

Camera camera() {
  Camera c;
  c.width = 8;
  c.height = 6;
  c.fx = c.fy = 8.0;
  c.cx = 4.0;
  c.cy = 3.0;
  return c;
}

// What a hook needs around it.
struct Fixture {
  Camera cam = camera();
  Gaussians model = random_model(40);
  Rng rng = Rng::stream(3, "dropout");
  std::unique_ptr<render::Rasterizer> rasterizer = render::make_cpu_rasterizer();
  std::vector<render::RenderCamera> cameras = {render::make_render_camera(cam)};
  MethodStep step(int t) { return MethodStep{t, 0, cam, model, rng, *rasterizer, cameras, {}}; }
};

TEST(Methods, Registry) {
  ASSERT_EQ(training_methods().size(), 3u);
  EXPECT_STREQ(training_methods()[0].name, "3dgs");
  EXPECT_EQ(training_method_names(), "3dgs, dropgaussian or d2gs");
  for (const MethodInfo& m : training_methods()) {
    TrainConfig c;
    c.method = m.name;
    EXPECT_STREQ(make_training_method(c)->name(), m.name);
    EXPECT_EQ(find_training_method(m.name), &m);
  }
  EXPECT_EQ(find_training_method("nerf"), nullptr);
  TrainConfig c;
  c.method = "nerf";
  EXPECT_EQ(test::error_of([&] { (void)make_training_method(c); }), "unknown method 'nerf' (expected 3dgs, dropgaussian or d2gs)");
}

TEST(Methods, Gs3dHasNoHooks) {
  Fixture f;
  TrainConfig c;
  auto m = make_training_method(c);
  const Rng::State before = f.rng.state();
  const OpacityMultiplier mult = m->opacity_multiplier(f.step(10));
  EXPECT_EQ(mult.values, nullptr);
  EXPECT_EQ(mult.drop_fraction, 0.0);
  const Rng::State after = f.rng.state();
  EXPECT_EQ(std::memcmp(after.words, before.words, sizeof before.words), 0);  // draws nothing
  EXPECT_TRUE(m->state().floats.empty() && m->state().bytes.empty());
  // A checkpoint holding state it does not keep is refused.
  MethodState s;
  s.floats["density_cache"] = {{0.5f}};
  EXPECT_EQ(test::error_of([&] { m->check_state(s, {}, 0); }), "it holds state 'density_cache', which --method 3dgs does not keep");
}

TEST(Methods, DropGaussianIsItsMaskAndRate) {
  Fixture f;
  TrainConfig c;
  c.method = "dropgaussian";
  c.iterations = 100;
  auto m = make_training_method(c);
  Rng same = f.rng;
  const OpacityMultiplier mult = m->opacity_multiplier(f.step(50));
  std::vector<float> expected;
  dropgaussian_mask(f.model.size(), dropgaussian_rate(50, 100, c.dropgaussian_max_rate), same, expected);
  ASSERT_NE(mult.values, nullptr);
  EXPECT_EQ(std::vector<float>(mult.values, mult.values + f.model.size()), expected);
  EXPECT_EQ(mult.drop_fraction, drop_fraction(expected));
  EXPECT_GT(mult.drop_fraction, 0.0);
}

TEST(Methods, D2gsDensityCacheThroughDensification) {
  Fixture f;
  TrainConfig c;
  c.method = "d2gs";
  c.dafe.enabled = false;
  c.dd_drop.release_density_cache = false;  // the paper: children inherit their parent's score
  auto m = make_training_method(c);
  m->start(c, MethodRun{Scene{}, Split{}, {}, {}}, [] { return CachedTrainingGeometry{}; });
  Rng same = f.rng;
  const OpacityMultiplier mult = m->opacity_multiplier(f.step(1));
  const std::vector<float> density = density_scores(f.model);
  std::vector<float> expected;
  bernoulli_mask(dd_drop_probabilities(gaussian_depths(f.model, f.cam, c.dd_drop.depth_mode), density, c.dd_drop, 1),
                 same, expected, c.dd_drop.compensate);
  EXPECT_EQ(std::vector<float>(mult.values, mult.values + f.model.size()), expected);
  EXPECT_EQ(m->state().floats.at("density_cache").front(), density);
  // Densification: rows 3, 3, 0 of the old model.
  DensifyReport report;
  report.source = {3, 3, 0};
  m->after_densify(report);
  EXPECT_EQ(m->state().floats.at("density_cache").front(), (std::vector<float>{density[3], density[3], density[0]}));
  // The release's cache keeps its length.
  c.dd_drop.release_density_cache = true;
  auto release = make_training_method(c);
  (void)release->opacity_multiplier(f.step(1));
  release->after_densify(report);
  EXPECT_EQ(release->state().floats.at("density_cache").front(), density);
  // And back from a checkpoint.
  auto again = make_training_method(c);
  again->restore(m->state());
  EXPECT_EQ(again->state(), m->state());
}

TEST(Methods, D2gsDafeTermAndItsGradient) {
  TrainConfig c;
  c.method = "d2gs";
  c.dafe.lambda = 0.5f;
  auto m = make_training_method(c);
  Scene scene;
  scene.cameras = {camera()};
  Split split;
  split.train = {0};
  m->start(c, MethodRun{scene, split, {}, {}}, [] { return CachedTrainingGeometry{}; });
  MethodState s;
  s.bytes["dafe_masks"] = {std::vector<std::uint8_t>(48, 0)};
  for (int i = 0; i < 12; ++i) s.bytes["dafe_masks"][0][static_cast<std::size_t>(i)] = 1;
  const auto mask = s.bytes["dafe_masks"][0];
  m->restore(std::move(s));
  Fixture f;
  std::vector<float> pred(144), grad(144, 0.0f), expected_grad(144, 0.0f);
  Image target(8, 6, 3);
  for (std::size_t i = 0; i < pred.size(); ++i) {
    pred[i] = static_cast<float>(i % 7) / 7.0f;
    target.pixels[i] = static_cast<float>(i % 5) / 5.0f;
  }
  const MethodStep step = f.step(1);
  const auto terms = m->loss_terms(MethodLoss{step, pred.data(), target, 8, 6, 3, grad.data()});
  ASSERT_EQ(terms.size(), 1u);
  EXPECT_EQ(terms[0].name, "dafe");
  EXPECT_EQ(terms[0].weight, 0.5);
  const double value = dafe_loss(pred.data(), target.pixels.data(), 8, 6, 3, mask, c.dafe.loss_form, expected_grad.data(), 0.5f);
  EXPECT_EQ(terms[0].value, value);
  EXPECT_GT(value, 0.0);
  EXPECT_EQ(grad, expected_grad);
}

TEST(Methods, D2gsChecksItsCheckpointState) {
  TrainConfig c;
  c.method = "d2gs";
  auto m = make_training_method(c);
  RunIdentity run;
  run.train_views = {1, 10, 19};
  run.train_sizes = {{{8, 6}}, {{8, 6}}, {{8, 6}}};
  MethodState s;
  s.floats["density_cache"] = {std::vector<float>(15, 0.5f)};
  s.bytes["dafe_masks"] = {std::vector<std::uint8_t>(48, 1), {}, std::vector<std::uint8_t>(48, 0)};
  EXPECT_EQ(test::error_of([&] { m->check_state(s, run, 15); }), "");
  s.bytes["dafe_masks"].pop_back();
  EXPECT_EQ(test::error_of([&] { m->check_state(s, run, 15); }), "it holds 2 DAFE masks for 3 training views");
  s.bytes["dafe_masks"] = {std::vector<std::uint8_t>(48, 1), std::vector<std::uint8_t>(47, 1), {}};
  EXPECT_EQ(test::error_of([&] { m->check_state(s, run, 15); }), "its DAFE mask of training view 10 has 47 pixels, the view 48");
  s.bytes["dafe_masks"].clear();  // none yet: allowed
  EXPECT_EQ(test::error_of([&] { m->check_state(s, run, 15); }), "");
  // A cache of another size than the checkpoint's model (densification would read past it), unless the
  // release's out-of-step cache is asked for.
  ASSERT_TRUE(c.dd_drop.release_density_cache);  // the default, as released
  EXPECT_EQ(test::error_of([&] { m->check_state(s, run, 16); }), "");
  c.dd_drop.release_density_cache = false;
  EXPECT_EQ(test::error_of([&] { make_training_method(c)->check_state(s, run, 16); }),
            "its density cache holds 15 scores for a model of 16 Gaussians");
  s.bytes["other"] = {};
  EXPECT_EQ(test::error_of([&] { m->check_state(s, run, 15); }), "it holds state 'other', which --method d2gs does not keep");
}

// ---- regularisers (--regularisers): components stacked on any method ----

// The per-view maps of D²GS's DAFE priors and of stereo-depth (train/view_map.hpp): DIR/NAME.npy at the
// view's size, 0 kept out of the average where it means "no value", and errors that name the file.
TEST(Methods, ViewMapsAreReadAtTheViewsSizeAndErrorsNameTheFile) {
  const auto dir = test::scratch_dir();
  Camera cam;
  cam.image_name = "view.png";
  cam.width = 2;
  cam.height = 1;
  // 2 rows × 4 columns: the left output pixel covers {1, 0, 1, 0}, the right one {3, 3, 3, 3}.
  write_npy_f32(dir / "view.npy", {2, 4}, {1, 0, 3, 3, 1, 0, 3, 3});
  EXPECT_EQ(read_view_map(dir, cam, {.what = "prior", .shape = "map"}).pixels, (std::vector<float>{0.5f, 3.0f}));
  EXPECT_EQ(read_view_map(dir, cam, {.what = "prior", .shape = "map", .zero_is_none = true}).pixels,
            (std::vector<float>{1.0f, 3.0f}));
  Camera full = cam;
  full.width = 4;
  full.height = 2;
  const Image same = read_view_map(dir, full, {.what = "prior", .shape = "map", .zero_is_none = true});
  EXPECT_EQ(same.width, 4);
  EXPECT_EQ(same.height, 2);
  EXPECT_EQ(same.pixels, (std::vector<float>{1, 0, 3, 3, 1, 0, 3, 3}));

  const std::string file = (dir / "view.npy").string();
  write_npy_f32(dir / "view.npy", {2, 4}, {1, 0, -1, 3, 1, 0, 3, 3});
  EXPECT_EQ(test::error_of([&] { read_view_map(dir, full, {.what = "d", .shape = "depth map", .check_depths = true}); }),
            file + ": depth -1 at pixel 2 is not a depth (≥ 0, 0 = none)");
  EXPECT_EQ(read_view_map(dir, full, {.what = "prior", .shape = "map"}).pixels[2], -1.0f);
  write_npy_f32(dir / "view.npy", {8}, {1, 0, 3, 3, 1, 0, 3, 3});
  EXPECT_EQ(test::error_of([&] { read_view_map(dir, cam, {.what = "stereo depth", .shape = "depth map"}); }),
            file + ": expected an H×W depth map, got 1 dimensions");
  // Maps that would leave nothing to act on, silently: non-finite values, no value at all, another shape.
  write_npy_f32(dir / "view.npy", {2, 4}, {1, 0, 3, std::nanf(""), 1, 0, 3, 3});
  EXPECT_EQ(test::error_of([&] { read_view_map(dir, full, {.what = "prior", .shape = "map"}); }),
            file + ": value nan at pixel 3 is not a finite number");
  write_npy_f32(dir / "view.npy", {2, 4}, {0, 0, -1, 0, 0, 0, -2, 0});
  EXPECT_EQ(test::error_of([&] { read_view_map(dir, full, {.what = "prior", .shape = "map", .zero_is_none = true}); }),
            file + ": holds no value for training view view.png (every pixel is 0, which means none, or below)");
  EXPECT_EQ(read_view_map(dir, full, {.what = "prior", .shape = "map"}).pixels[2], -1.0f);  // a disparity may be < 0
  write_npy_f32(dir / "view.npy", {4, 4}, std::vector<float>(16, 2.0f));
  EXPECT_EQ(test::error_of([&] { read_view_map(dir, full, {.what = "prior", .shape = "map"}); }),
            file + ": is 4×4, training view view.png is 4×2: another aspect ratio, so not this view's map");
  cam.image_name = "other.jpg";
  EXPECT_EQ(test::error_of([&] { read_view_map(dir, cam, {.what = "DAFE prior", .shape = "map"}); }),
            (dir / "other.npy").string() + ": DAFE prior missing for training view other.jpg");
}

TEST(Regularisers, RegistryAndNames) {
  ASSERT_EQ(training_regularisers().size(), 5u);
  EXPECT_STREQ(training_regularisers()[0].name, "opacity-noise");
  EXPECT_STREQ(training_regularisers()[1].name, "opacity-decay");
  EXPECT_STREQ(training_regularisers()[2].name, "stereo-depth");
  EXPECT_STREQ(training_regularisers()[3].name, "anisotropy");
  EXPECT_STREQ(training_regularisers()[4].name, "scale-l1");
  TrainConfig c;
  c.method = "dropgaussian";
  c.regularisers = {"opacity-decay", "opacity-noise"};
  EXPECT_STREQ(make_training_method(c)->name(), "dropgaussian");  // the run's method, whatever is stacked on it
  c.regularisers = {"weight-decay"};
  EXPECT_EQ(test::error_of([&] { (void)make_training_method(c); }), "unknown regulariser 'weight-decay'");
  c.regularisers = {"opacity-noise", "opacity-noise"};
  EXPECT_EQ(test::error_of([&] { (void)make_training_method(c); }), "regulariser 'opacity-noise' is named twice");
}

TEST(Regularisers, OpacityNoiseIsClippedGaussianCappedAtOneAndStateless) {
  Fixture f;
  f.model = random_model(20000);
  for (std::size_t i = 0; i < f.model.size(); ++i) f.model.opacity_logits[i] = 3.0f * static_cast<float>(i % 7) - 9.0f;
  TrainConfig c;
  c.regularisers = {"opacity-noise"};
  c.opacity_noise_sigma = 0.5;
  auto m = make_training_method(c);
  const Rng::State before = f.rng.state();
  const OpacityMultiplier mult = m->opacity_multiplier(f.step(7));
  EXPECT_EQ(std::memcmp(f.rng.state().words, before.words, sizeof before.words), 0);  // the dropout stream untouched
  ASSERT_NE(mult.values, nullptr);
  EXPECT_EQ(mult.drop_fraction, 0.0);
  const std::vector<float> values(mult.values, mult.values + f.model.size());
  std::size_t at_bound = 0, uncapped = 0;
  double sum = 0.0;
  for (std::size_t i = 0; i < values.size(); ++i) {
    const double o = 1.0 / (1.0 + std::exp(-static_cast<double>(f.model.opacity_logits[i])));
    const double m_i = values[i];
    EXPECT_GE(m_i, 0.5 - 1e-6);
    EXPECT_LE(m_i, 1.5 + 1e-6);
    EXPECT_LE(o * m_i, 1.0 + 1e-6) << i;  // o·(1 + ε) capped at 1
    if (o < 0.6) {                        // 1 + ε ≤ 1.5 < 1/o: never capped
      ++uncapped;
      sum += m_i;
      at_bound += std::abs(std::abs(m_i - 1.0) - 0.5) < 1e-6;
    }
  }
  ASSERT_GT(uncapped, 10000u);
  // ε ~ N(0, σ²) clipped to [−σ, σ]: mean 0, and P(|ε| = σ) = P(|Z| ≥ 1) = 0.3173.
  EXPECT_NEAR(sum / static_cast<double>(uncapped), 1.0, 0.01);
  EXPECT_NEAR(static_cast<double>(at_bound) / static_cast<double>(uncapped), 0.3173, 0.015);
  // The noise of an iteration depends on the seed and the iteration only: no state to checkpoint.
  auto again = make_training_method(c);
  const OpacityMultiplier same = again->opacity_multiplier(f.step(7));
  EXPECT_EQ(std::vector<float>(same.values, same.values + f.model.size()), values);
  const OpacityMultiplier next = again->opacity_multiplier(f.step(8));
  EXPECT_NE(std::vector<float>(next.values, next.values + f.model.size()), values);
  EXPECT_TRUE(m->state().floats.empty() && m->state().bytes.empty());
  c.seed = 1;
  const OpacityMultiplier other_seed = make_training_method(c)->opacity_multiplier(f.step(7));
  EXPECT_NE(std::vector<float>(other_seed.values, other_seed.values + f.model.size()), values);
}

TEST(Regularisers, OpacityDecayScalesTheOpacityAfterDensifyFrom) {
  Fixture f;
  TrainConfig c;
  c.regularisers = {"opacity-decay"};
  c.opacity_decay_factor = 0.9;
  c.densify_from = 500;
  auto m = make_training_method(c);
  f.model.opacity_logits = {-200.0f, -12.0f, -3.0f, 0.0f, 0.5f, 4.0f, 16.0f};
  const std::vector<float> before = f.model.opacity_logits;
  m->before_update(500, f.model);  // Binocular3DGS: from the iteration after densify_from_iter
  EXPECT_EQ(f.model.opacity_logits, before);
  m->before_update(501, f.model);
  for (std::size_t i = 0; i < before.size(); ++i) {
    const double o = 1.0 / (1.0 + std::exp(-static_cast<double>(before[i])));
    const double decayed = 1.0 / (1.0 + std::exp(-static_cast<double>(f.model.opacity_logits[i])));
    EXPECT_TRUE(std::isfinite(f.model.opacity_logits[i])) << i;
    EXPECT_NEAR(decayed / o, 0.9, 1e-5) << "logit " << before[i];
  }
  EXPECT_NEAR(f.model.opacity_logits[0], -200.0f + std::log(0.9f), 1e-4);  // underflowing opacity: l + log f
  // Nothing else of the model changes, and the decay keeps no state.
  EXPECT_TRUE(m->state().floats.empty() && m->state().bytes.empty());
}

// The anisotropy term against its formula, computed independently in double, and its gradient against central
// differences of that formula; it adds to the gradient it is given and leaves every other parameter alone.
TEST(Regularisers, AnisotropyHingeOnTheLogAxisRatioAndItsGradient) {
  TrainConfig c;
  c.regularisers = {"anisotropy"};
  c.anisotropy_ratio = 10.0;
  c.anisotropy_lambda = 0.7;
  auto m = make_training_method(c);
  Gaussians model = random_model(6);
  model.log_scales = {0.0f,  0.5f,  -1.0f,   // ratio e^1.5 = 4.5: inside, no term
                      -3.0f, 0.2f,  -0.4f,   // ratio e^3.2 = 24.5: beyond
                      1.0f,  -6.0f, 0.5f,    // ratio e^7: beyond, the smallest axis in the middle
                      -2.0f, -2.0f, -2.0f,   // isotropic
                      4.0f,  -9.0f, -9.0f,   // a needle: two equal small axes (the first is taken)
                      0.5f,  0.5f,  -2.0f};  // a disc: two equal large axes (the first is taken)
  const auto formula = [&](const std::vector<float>& s) {
    double sum = 0.0;
    for (std::size_t i = 0; i < s.size() / 3; ++i) {
      const double hi = std::max({s[3 * i], s[3 * i + 1], s[3 * i + 2]});
      const double lo = std::min({s[3 * i], s[3 * i + 1], s[3 * i + 2]});
      sum += std::max(0.0, hi - lo - std::log(10.0));
    }
    return sum / static_cast<double>(s.size() / 3);
  };
  Gaussians grad = model;
  for (auto* a : {&grad.means, &grad.log_scales, &grad.quats, &grad.opacity_logits, &grad.sh_dc, &grad.sh_rest})
    std::fill(a->begin(), a->end(), 0.25f);  // the render's gradient, which the term adds to
  const Gaussians before = grad;
  const std::vector<LossTerm> terms = m->parameter_terms(12, model, grad);
  ASSERT_EQ(terms.size(), 1u);
  EXPECT_EQ(terms[0].name, "anisotropy");
  EXPECT_EQ(terms[0].weight, 0.7);
  EXPECT_NEAR(terms[0].value, formula(model.log_scales), 1e-6);
  EXPECT_NEAR(terms[0].value, (3.2 + 7.0 + 13.0 + 2.5 - 4 * std::log(10.0)) / 6.0, 1e-6);
  for (std::size_t k = 0; k < 12; ++k) {  // the Gaussians without tied axes (ties: a subgradient, below)
    std::vector<float> plus = model.log_scales, minus = model.log_scales;
    const float h = 1e-3f;
    plus[k] += h;
    minus[k] -= h;
    const double numeric = 0.7 * (formula(plus) - formula(minus)) / (2.0 * h);
    EXPECT_NEAR(grad.log_scales[k] - 0.25f, numeric, 1e-4) << "log-scale " << k;
  }
  EXPECT_FLOAT_EQ(grad.log_scales[0] - 0.25f, 0.0f);  // inside the ratio: no gradient at all
  EXPECT_FLOAT_EQ(grad.log_scales[12] - 0.25f, 0.7f / 6.0f);
  EXPECT_FLOAT_EQ(grad.log_scales[13] - 0.25f, -0.7f / 6.0f);
  EXPECT_FLOAT_EQ(grad.log_scales[14] - 0.25f, 0.0f);
  EXPECT_FLOAT_EQ(grad.log_scales[15] - 0.25f, 0.7f / 6.0f);
  EXPECT_FLOAT_EQ(grad.log_scales[16] - 0.25f, 0.0f);
  EXPECT_FLOAT_EQ(grad.log_scales[17] - 0.25f, -0.7f / 6.0f);
  EXPECT_EQ(grad.means, before.means);
  EXPECT_EQ(grad.quats, before.quats);
  EXPECT_EQ(grad.opacity_logits, before.opacity_logits);
  EXPECT_EQ(grad.sh_dc, before.sh_dc);
  EXPECT_TRUE(m->state().floats.empty() && m->state().bytes.empty());

  // Stacked on a method, the term comes after the method's (none for DropGaussian) and adds the same gradient.
  TrainConfig stacked = c;
  stacked.method = "dropgaussian";
  Gaussians grad2 = before;
  const std::vector<LossTerm> again = make_training_method(stacked)->parameter_terms(12, model, grad2);
  ASSERT_EQ(again.size(), 1u);
  EXPECT_EQ(again[0].value, terms[0].value);
  EXPECT_EQ(grad2.log_scales, grad.log_scales);
  // Without the regulariser no method has parameter terms.
  stacked.regularisers = {};
  Gaussians grad3 = before;
  EXPECT_TRUE(make_training_method(stacked)->parameter_terms(12, model, grad3).empty());
  EXPECT_EQ(grad3.log_scales, before.log_scales);
}

// The scale-l1 term against its formula, λ · mean over the N×3 entries of exp(s), computed independently in
// double, and its gradient on the log-scales against central differences; nothing else is touched.
TEST(Regularisers, ScaleL1IsTheMeanScaleAndItsGradient) {
  TrainConfig c;
  c.regularisers = {"scale-l1"};
  c.scale_l1_lambda = 0.3;
  auto m = make_training_method(c);
  Gaussians model = random_model(5);
  model.log_scales[4] = 3.0f;    // a large axis: e³ ≈ 20, its gradient 20 times an axis of size 1
  model.log_scales[9] = -12.0f;  // a tiny one: almost no gradient
  const auto formula = [](const std::vector<double>& s) {
    double sum = 0.0;
    for (double v : s) sum += std::exp(v);
    return sum / static_cast<double>(s.size());
  };
  const std::vector<double> log_scales(model.log_scales.begin(), model.log_scales.end());
  Gaussians grad = model;
  for (auto* a : {&grad.means, &grad.log_scales, &grad.quats, &grad.opacity_logits, &grad.sh_dc, &grad.sh_rest})
    std::fill(a->begin(), a->end(), -0.5f);
  const Gaussians before = grad;
  const std::vector<LossTerm> terms = m->parameter_terms(3, model, grad);
  ASSERT_EQ(terms.size(), 1u);
  EXPECT_EQ(terms[0].name, "scale_l1");
  EXPECT_EQ(terms[0].weight, 0.3);
  EXPECT_NEAR(terms[0].value, formula(log_scales), 1e-6 * terms[0].value);
  for (std::size_t k = 0; k < log_scales.size(); ++k) {
    std::vector<double> plus = log_scales, minus = log_scales;
    const double h = 1e-4;
    plus[k] += h;
    minus[k] -= h;
    const double numeric = 0.3 * (formula(plus) - formula(minus)) / (2.0 * h);
    EXPECT_NEAR(grad.log_scales[k] + 0.5f, numeric, 1e-5 + 1e-5 * std::abs(numeric)) << "log-scale " << k;
  }
  EXPECT_NEAR(grad.log_scales[4] + 0.5f, 0.3 * std::exp(3.0) / 15.0, 1e-5);
  EXPECT_EQ(grad.means, before.means);
  EXPECT_EQ(grad.quats, before.quats);
  EXPECT_EQ(grad.opacity_logits, before.opacity_logits);
  EXPECT_EQ(grad.sh_dc, before.sh_dc);
  EXPECT_EQ(grad.sh_rest, before.sh_rest);
  EXPECT_TRUE(m->state().floats.empty() && m->state().bytes.empty());
  // λ = 0: the term is logged but adds nothing.
  c.scale_l1_lambda = 0.0;
  Gaussians grad0 = before;
  (void)make_training_method(c)->parameter_terms(3, model, grad0);
  EXPECT_EQ(grad0.log_scales, before.log_scales);
}

TEST(Regularisers, StackMultipliesMultipliersAndNamespacesState) {
  Fixture f;
  TrainConfig c;
  c.method = "d2gs";
  c.dafe.enabled = false;
  c.regularisers = {"opacity-noise"};
  auto stacked = make_training_method(c);
  stacked->start(c, MethodRun{Scene{}, Split{}, {}, {}}, [] { return CachedTrainingGeometry{}; });
  TrainConfig alone = c;
  alone.regularisers = {};
  auto method = make_training_method(alone);
  method->start(alone, MethodRun{Scene{}, Split{}, {}, {}}, [] { return CachedTrainingGeometry{}; });
  TrainConfig noise_only;
  noise_only.regularisers = {"opacity-noise"};
  auto noise = make_training_method(noise_only);

  Rng rng_copy = f.rng;
  const OpacityMultiplier product = stacked->opacity_multiplier(f.step(3));
  f.rng = rng_copy;  // the method draws what it draws alone
  const OpacityMultiplier dd = method->opacity_multiplier(f.step(3));
  const OpacityMultiplier eps = noise->opacity_multiplier(f.step(3));
  ASSERT_NE(product.values, nullptr);
  for (std::size_t i = 0; i < f.model.size(); ++i) EXPECT_EQ(product.values[i], dd.values[i] * eps.values[i]) << i;
  EXPECT_EQ(product.drop_fraction, dd.drop_fraction);  // the noise drops nothing

  // The method's state keeps its names; a regulariser's would be under "NAME/".
  const MethodState s = stacked->state();
  EXPECT_EQ(s.floats.count("density_cache"), 1u);
  EXPECT_EQ(s, method->state());
  MethodState extra = s;
  extra.bytes["opacity-noise/rng"] = {{1, 2, 3}};
  EXPECT_EQ(test::error_of([&] { stacked->check_state(extra, {}, f.model.size()); }),
            "regulariser opacity-noise: it holds state 'rng', which --method opacity-noise does not keep");
  EXPECT_EQ(test::error_of([&] { stacked->check_state(s, {}, f.model.size()); }), "");
}

}  // namespace
}  // namespace d2gs
