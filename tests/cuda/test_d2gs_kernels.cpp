// D²GS's own stages as kernels against the CPU reference: DD-Drop's probabilities
// (train/kernels/dd_drop_kernels.hpp) against train/dropout.cpp's dd_drop_probabilities of gaussian_depths,
// and the DAFE loss with its gradient (train/kernels/dafe_kernels.hpp) against train/losses.cpp's dafe_loss:
// through the CPU emulator always, on the GPU when there is one.
//
// The probabilities are the CPU's arithmetic (train/dd_drop_math.hpp) on the CPU's depths, with the minimum,
// maximum and tertile thresholds read from the depths' sorted keys where the CPU selects them: bit for bit.
// The DAFE gradient is the CPU's expression with the same float scale (the masked count is exact): bit for
// bit, added to what the buffer held. The DAFE value is a double sum of the same float terms in another,
// fixed order: within 1e-12 relative.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <random>
#include <string>

#include <glm/gtc/quaternion.hpp>

#include "d2gs/core/error.hpp"
#include "d2gs/core/image.hpp"
#include "d2gs/core/random.hpp"
#include "d2gs/render/cuda/device.hpp"
#include "d2gs/scene/scene.hpp"
#include "d2gs/train/dropout.hpp"
#include "d2gs/train/kernels/optim.hpp"
#include "d2gs/train/losses.hpp"
#include "test_paths.hpp"

namespace d2gs::test {
namespace {

namespace emulate = render::kernels::emulate;
namespace tk = train_kernels;

// The index of the first value whose bits differ, or -1.
long long first_difference(const std::vector<float>& a, const std::vector<float>& b) {
  if (a.size() != b.size()) return 0;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (std::memcmp(&a[i], &b[i], sizeof(float)) != 0) return static_cast<long long>(i);
  return -1;
}

void expect_bit_equal(const std::vector<float>& kernel, const std::vector<float>& cpu, const std::string& what) {
  ASSERT_EQ(kernel.size(), cpu.size()) << what;
  const long long i = first_difference(kernel, cpu);
  EXPECT_EQ(i, -1) << what << ": first difference at " << i << ": " << kernel[static_cast<std::size_t>(std::max(0LL, i))]
                   << " vs " << cpu[static_cast<std::size_t>(std::max(0LL, i))];
}

void expect_same_stream(Rng a, Rng b, const std::string& what) {
  const auto sa = a.state(), sb = b.state();
  for (int k = 0; k < 4; ++k) EXPECT_EQ(sa.words[k], sb.words[k]) << what << " word " << k;
}

// ---- DD-Drop -------------------------------------------------------------------------------------------

// A camera at a random centre with a random rotation.
Camera random_camera(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Camera cam;
  cam.width = 64;
  cam.height = 48;
  cam.R_world_to_cam = glm::mat3_cast(glm::normalize(glm::dquat(n(rng), n(rng), n(rng), n(rng))));
  cam.t_world_to_cam = glm::dvec3(n(rng), n(rng), 3.0 + n(rng));
  return cam;
}

// n Gaussians: normal means, with repeated positions (equal depths at the tertile ranks) every 7th.
Gaussians random_model(std::size_t n, std::mt19937& rng) {
  Gaussians g;
  g.resize(n, 0);
  std::normal_distribution<float> d(0.0f, 2.0f);
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t k = 0; k < 3; ++k) g.means[3 * i + k] = i % 7 == 6 ? g.means[3 * (i / 2) + k] : d(rng);
  return g;
}

// Density scores in [0, 1] as the method gives them: minmax of −(mean kNN distance)-like values, exact 0s
// and 1s, some repeated; or every score 0.5 (the release's cache after growth).
std::vector<float> random_density(std::size_t n, std::mt19937& rng, bool constant) {
  if (constant) return std::vector<float>(n, 0.5f);
  std::uniform_real_distribution<float> u(0.0f, 3.0f);
  std::vector<float> rho(n);
  for (auto& v : rho) v = -u(rng);
  return minmax(rho);
}

// Option sets covering both depth formulas, the ablation switches and the rate schedule's ends.
std::vector<DdDropOptions> option_sets() {
  std::vector<DdDropOptions> sets;
  DdDropOptions paper;  // the paper's: Euclidean depth, w 0.5 / 0.5
  sets.push_back(paper);
  DdDropOptions release = paper;
  release.depth_mode = DepthMode::ReleaseDot;
  release.weight_depth = 0.3;
  release.weight_density = 0.7;
  sets.push_back(release);
  DdDropOptions no_layers = release;
  no_layers.use_layers = false;
  no_layers.rate_max = 0.9;
  sets.push_back(no_layers);
  DdDropOptions depth_only = paper;
  depth_only.use_density_score = false;
  depth_only.compensate = true;
  depth_only.lambda_near = 3.0;  // λ·S·r above 1: clamped
  depth_only.rate_max = 1.0;
  sets.push_back(depth_only);
  DdDropOptions density_only = release;
  density_only.use_depth_score = false;
  density_only.rate_iterations = 1;
  sets.push_back(density_only);
  return sets;
}

template <class Kernel>
void expect_probabilities_equal(const Gaussians& model, const Camera& cam, const std::vector<float>& density,
                                const DdDropOptions& o, int iteration, Kernel kernel, const std::string& what) {
  const auto cpu = dd_drop_probabilities(gaussian_depths(model, cam, o.depth_mode), density, o, iteration);
  expect_bit_equal(kernel(model, cam, density, o, iteration), cpu, what);
}

template <class Kernel>
void expect_random_probabilities_equal(Kernel kernel, const std::string& what, bool many_sizes) {
  std::mt19937 rng(17);
  const auto sets = option_sets();
  std::vector<std::size_t> sizes = {0, 1, 2, 3, 4, 100, 301, 10007};
  if (many_sizes) sizes.push_back(70001);
  int case_index = 0;
  for (std::size_t n : sizes)
    for (std::size_t s = 0; s < sets.size(); ++s, ++case_index) {
      const Gaussians model = random_model(n, rng);
      const Camera cam = random_camera(rng);
      const auto density = random_density(n, rng, case_index % 4 == 3);
      const int iteration = std::array<int, 4>{1, 500, 7321, 20000}[static_cast<std::size_t>(case_index % 4)];
      expect_probabilities_equal(model, cam, density, sets[s], iteration, kernel,
                                 what + " n " + std::to_string(n) + " options " + std::to_string(s) + " iteration " +
                                     std::to_string(iteration));
    }
}

// Depths that tie and change sign: a camera at the origin looking along +z (release depth = z exactly),
// Gaussians at z ∈ {−1, −0, +0, 1, 2} repeated, and every Gaussian at one depth (range 0: minmax gives 0).
template <class Kernel>
void expect_tied_probabilities_equal(Kernel kernel, const std::string& what) {
  Camera cam;
  Gaussians model;
  const float zs[] = {-1.0f, -0.0f, 0.0f, 1.0f, 2.0f, 0.0f, -0.0f};
  model.resize(301, 0);
  for (std::size_t i = 0; i < model.size(); ++i) {
    const float z = zs[i % 7];
    model.means[3 * i] = std::signbit(z) ? -1.0f : 1.0f;  // x·0 is −0 for negative x: the dot stays −0
    model.means[3 * i + 1] = std::signbit(z) ? -2.0f : 2.0f;
    model.means[3 * i + 2] = z;
  }
  std::mt19937 rng(5);
  const auto density = random_density(model.size(), rng, false);
  for (const auto& o : option_sets()) {
    if (o.depth_mode != DepthMode::ReleaseDot) continue;
    expect_probabilities_equal(model, cam, density, o, 5000, kernel, what + " ties");
    Gaussians flat = model;
    for (std::size_t i = 0; i < flat.size(); ++i) flat.means[3 * i + 2] = 0.5f;
    expect_probabilities_equal(flat, cam, density, o, 5000, kernel, what + " constant depth");
  }
  // The ties must reach the tertile ranks for the case to mean anything: 43 depths −1, 172 zeros of either
  // sign, 86 above; ranks 99 and 201 are zeros, so both thresholds are a zero: 43 near, 258 far.
  const auto layers = depth_layers(gaussian_depths(model, cam, DepthMode::ReleaseDot));
  EXPECT_EQ(std::count(layers.begin(), layers.end(), 0), 43);
  EXPECT_EQ(std::count(layers.begin(), layers.end(), 2), 258);
}

// Fern: the dataset's SfM points as Gaussians, the three training cameras of the 3-view split (images 1,
// 10, 19), kNN density scores.
struct Fern {
  Scene scene;
  Gaussians model;
  std::vector<float> density;
};
const Fern& fern() {
  static const Fern f = [] {
    SceneLoadOptions load;
    load.resolution = 8;
    Fern out;
    out.scene = load_scene(shared_data() / "nerf_llff_data/fern", load);
    out.model.resize(out.scene.sfm_points.size(), 0);
    for (std::size_t i = 0; i < out.model.size(); ++i)
      for (int k = 0; k < 3; ++k)
        out.model.means[3 * i + static_cast<std::size_t>(k)] = out.scene.sfm_points.positions[i][k];
    out.density = density_scores(out.model);
    return out;
  }();
  return f;
}

template <class Kernel>
void expect_fern_probabilities_equal(Kernel kernel, const std::string& what) {
  const Fern& f = fern();
  ASSERT_GT(f.model.size(), 1000u);
  for (int view : {1, 10, 19})
    for (const auto& o : option_sets())
      expect_probabilities_equal(f.model, f.scene.cameras.at(static_cast<std::size_t>(view)), f.density, o, 5000,
                                 kernel, what + " fern view " + std::to_string(view));
}

// The probabilities and the mask from them in one go: the CPU's method step (d2gs.cpp: probabilities, then
// bernoulli_mask) draw for draw, the stream left where the CPU leaves it.
template <class Mask>
void expect_fern_mask_equal(Mask kernel_mask, const std::string& what) {
  const Fern& f = fern();
  for (const auto& o : option_sets()) {
    const Camera& cam = f.scene.cameras.at(10);
    Rng cpu_rng = Rng::stream(11, "dropout"), kernel_rng = cpu_rng;
    const auto cpu_p = dd_drop_probabilities(gaussian_depths(f.model, cam, o.depth_mode), f.density, o, 3000);
    std::vector<float> cpu, kernel, kernel_p;
    bernoulli_mask(cpu_p, cpu_rng, cpu, o.compensate);
    kernel_mask(f.model, cam, f.density, o, 3000, kernel_rng, kernel, &kernel_p);
    expect_bit_equal(kernel_p, cpu_p, what + " probabilities");
    expect_bit_equal(kernel, cpu, what + " mask");
    expect_same_stream(kernel_rng, cpu_rng, what);
  }
}

auto emulated_probabilities(emulate::Schedule schedule) {
  return [schedule](const Gaussians& m, const Camera& c, const std::vector<float>& d, const DdDropOptions& o, int t) {
    return tk::emulated_dd_drop_probabilities(m, c, d, o, t, schedule);
  };
}

TEST(EmulatedKernels, DdDropProbabilitiesEqualTheCpuBitForBit) {
  for (auto schedule : emulate::kAllSchedules)
    expect_random_probabilities_equal(emulated_probabilities(schedule), "emulated",
                                      schedule == emulate::Schedule::Forward);
}

TEST(EmulatedKernels, DdDropProbabilitiesWithTiedAndSignedZeroDepthsEqualTheCpu) {
  for (auto schedule : emulate::kAllSchedules) expect_tied_probabilities_equal(emulated_probabilities(schedule), "emulated");
}

TEST(EmulatedKernels, DdDropProbabilitiesOnFernEqualTheCpuBitForBit) {
  expect_fern_probabilities_equal(emulated_probabilities(emulate::Schedule::Forward), "emulated");
}

TEST(EmulatedKernels, DdDropMaskFromDeviceProbabilitiesEqualsTheCpuDrawForDraw) {
  expect_fern_mask_equal([](const Gaussians& m, const Camera& c, const std::vector<float>& d, const DdDropOptions& o,
                            int t, Rng& rng, std::vector<float>& mask, std::vector<float>* p) {
    tk::emulated_dd_drop_mask(m, c, d, o, t, rng, mask, p);
  }, "emulated");
  Gaussians model;
  model.resize(3, 0);
  std::vector<float> mask;
  Rng rng(1);
  EXPECT_THROW(tk::emulated_dd_drop_mask(model, Camera{}, std::vector<float>(2), DdDropOptions{}, 1, rng, mask), Error);
}

TEST(DeviceKernels, DdDropProbabilitiesEqualTheCpuBitForBit) {
  if (cuda::device_count() == 0) {
    Gaussians model;
    model.resize(3, 0);
    EXPECT_THROW(tk::device_dd_drop_probabilities(model, Camera{}, std::vector<float>(3), DdDropOptions{}, 1), Error);
    GTEST_SKIP() << cuda::describe_device();
  }
  const auto kernel = [](const Gaussians& m, const Camera& c, const std::vector<float>& d, const DdDropOptions& o,
                         int t) { return tk::device_dd_drop_probabilities(m, c, d, o, t); };
  expect_random_probabilities_equal(kernel, "device", true);
  expect_tied_probabilities_equal(kernel, "device");
  expect_fern_probabilities_equal(kernel, "device");
  expect_fern_mask_equal([](const Gaussians& m, const Camera& c, const std::vector<float>& d, const DdDropOptions& o,
                            int t, Rng& rng, std::vector<float>& mask, std::vector<float>* p) {
    tk::device_dd_drop_mask(m, c, d, o, t, rng, mask, p);
  }, "device");
}

// ---- DAFE ----------------------------------------------------------------------------------------------

struct DafeCase {
  int width = 0, height = 0, channels = 0;
  std::vector<float> a, b, grad;  // grad: what the buffer holds before DAFE (the L1 and SSIM gradients)
  std::vector<std::uint8_t> mask;
};

// A render a near a ground truth b, some values equal (sign 0), a far mask of the given density.
DafeCase random_case(int width, int height, int channels, double mask_density, unsigned seed) {
  DafeCase c{width, height, channels, {}, {}, {}, {}};
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::normal_distribution<float> g(0.0f, 1e-4f);
  const std::size_t pixels = static_cast<std::size_t>(width) * height, n = pixels * channels;
  c.a.resize(n);
  c.b.resize(n);
  c.grad.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    c.b[i] = u(rng);
    c.a[i] = i % 13 == 0 ? c.b[i] : std::clamp(0.7f * c.b[i] + 0.3f * u(rng), 0.0f, 1.0f);
    c.grad[i] = i % 11 == 0 ? -0.0f : g(rng);
  }
  c.mask.resize(pixels);
  for (auto& m : c.mask) m = u(rng) < mask_density ? static_cast<std::uint8_t>(1 + rng() % 255) : 0;
  return c;
}

// Fern's view 0 as the ground truth, a blend of views 0 and 1 as the render, the far mask from view 0's
// darkness taken as a disparity (the darkest 10 %, as dafe_mask's percentile rule picks).
DafeCase fern_case() {
  const auto dir = shared_data() / "nerf_llff_data/fern/images_8";
  const Image v0 = read_image(dir / "image000.png"), v1 = read_image(dir / "image001.png");
  DafeCase c{v0.width, v0.height, v0.channels, {}, v0.pixels, std::vector<float>(v0.pixels.size(), 0.0f), {}};
  c.a.resize(v0.pixels.size());
  for (std::size_t i = 0; i < c.a.size(); ++i) c.a[i] = std::clamp(0.8f * v0.pixels[i] + 0.25f * v1.pixels[i] - 0.02f, 0.0f, 1.0f);
  const std::size_t pixels = static_cast<std::size_t>(v0.width) * v0.height;
  std::vector<float> disparity(pixels);
  for (std::size_t p = 0; p < pixels; ++p)
    for (int k = 0; k < v0.channels; ++k) disparity[p] += v0.pixels[p * static_cast<std::size_t>(v0.channels) + static_cast<std::size_t>(k)];
  c.mask = dafe_mask(disparity, PriorKind::Disparity, DafeMaskRule::Percentile, 10.0);
  return c;
}

template <class Loss>
void expect_dafe_equal(const DafeCase& c, Loss kernel_loss, const std::string& what) {
  for (auto form : {DafeLossForm::Release, DafeLossForm::Paper})
    for (bool with_grad : {true, false}) {
      const std::string at = what + (form == DafeLossForm::Paper ? " paper" : " release") + (with_grad ? "" : " value only");
      std::vector<float> cpu_grad = c.grad, kernel_grad = c.grad;
      const float scale = 1.5f;
      const double cpu = dafe_loss(c.a.data(), c.b.data(), c.width, c.height, c.channels, c.mask, form,
                                   with_grad ? cpu_grad.data() : nullptr, scale);
      const double kernel = kernel_loss(c.a.data(), c.b.data(), c.width, c.height, c.channels, c.mask, form,
                                        with_grad ? kernel_grad.data() : nullptr, scale);
      EXPECT_NEAR(kernel, cpu, 1e-12 * std::abs(cpu)) << at;
      if (cpu == 0.0) {
        EXPECT_EQ(kernel, 0.0) << at;
      }
      expect_bit_equal(kernel_grad, cpu_grad, at + " gradient");
      if (with_grad && cpu != 0.0) {
        EXPECT_NE(first_difference(cpu_grad, c.grad), -1) << at << ": no gradient added";
      }
    }
}

template <class Loss>
void expect_random_dafe_equal(Loss kernel_loss, const std::string& what) {
  const int sizes[][3] = {{37, 23, 3}, {7, 4, 1}, {64, 48, 2}, {120, 90, 3}};
  unsigned seed = 1;
  for (const auto& s : sizes)
    for (double density : {0.0, 0.05, 0.5, 1.0})
      expect_dafe_equal(random_case(s[0], s[1], s[2], density, seed++), kernel_loss,
                        what + " " + std::to_string(s[0]) + "x" + std::to_string(s[1]) + "x" + std::to_string(s[2]) +
                            " mask " + std::to_string(density));
}

auto emulated_dafe(emulate::Schedule schedule) {
  return [schedule](const float* a, const float* b, int w, int h, int c, const std::vector<std::uint8_t>& mask,
                    DafeLossForm form, float* grad, float scale) {
    return tk::emulated_dafe_loss(a, b, w, h, c, mask, form, grad, scale, schedule);
  };
}

TEST(EmulatedKernels, DafeLossEqualsTheCpu) {
  for (auto schedule : emulate::kAllSchedules) expect_random_dafe_equal(emulated_dafe(schedule), "emulated");
  const DafeCase c = random_case(8, 8, 3, 0.5, 3);
  EXPECT_THROW(tk::emulated_dafe_loss(c.a.data(), c.b.data(), 8, 7, 3, c.mask, DafeLossForm::Release), Error);
}

TEST(EmulatedKernels, DafeLossOnFernEqualsTheCpu) {
  const DafeCase c = fern_case();
  ASSERT_EQ(c.width, 504);
  const auto masked = std::count_if(c.mask.begin(), c.mask.end(), [](std::uint8_t m) { return m != 0; });
  EXPECT_NEAR(static_cast<double>(masked) / static_cast<double>(c.mask.size()), 0.10, 0.01);
  for (auto schedule : {emulate::Schedule::Forward, emulate::Schedule::SyncVisibility})
    expect_dafe_equal(c, emulated_dafe(schedule), "emulated fern");
}

TEST(DeviceKernels, DafeLossEqualsTheCpu) {
  if (cuda::device_count() == 0) {
    const DafeCase c = random_case(8, 8, 3, 0.5, 3);
    EXPECT_THROW(tk::device_dafe_loss(c.a.data(), c.b.data(), 8, 8, 3, c.mask, DafeLossForm::Release), Error);
    GTEST_SKIP() << cuda::describe_device();
  }
  const auto kernel = [](const float* a, const float* b, int w, int h, int c, const std::vector<std::uint8_t>& mask,
                         DafeLossForm form, float* grad, float scale) {
    return tk::device_dafe_loss(a, b, w, h, c, mask, form, grad, scale);
  };
  expect_random_dafe_equal(kernel, "device");
  expect_dafe_equal(fern_case(), kernel, "device fern");
  // The fixed summation order: the device's value is the emulator's bit for bit.
  const DafeCase c = fern_case();
  for (auto form : {DafeLossForm::Release, DafeLossForm::Paper})
    EXPECT_EQ(kernel(c.a.data(), c.b.data(), c.width, c.height, c.channels, c.mask, form, nullptr, 1.0f),
              tk::emulated_dafe_loss(c.a.data(), c.b.data(), c.width, c.height, c.channels, c.mask, form));
}

}  // namespace
}  // namespace d2gs::test
