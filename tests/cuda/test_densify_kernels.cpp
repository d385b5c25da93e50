// The densification edits as kernels (train/kernels/densify_kernels.hpp, host side densify_pipeline.hpp)
// against train/densify.cpp: clone, split and prune through the CPU emulator always, on the GPU when
// there is one. The split's normals are the CPU's own draws (the Rng stream jumped ahead in parallel),
// the rows are scattered in the CPU's order, so the emulated model, moments, statistics, report and the
// stream afterwards must be the CPU's bit for bit.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <functional>
#include <random>
#include <string>

#include "d2gs/core/random.hpp"
#include "d2gs/render/cuda/device.hpp"
#include "d2gs/scene/scene.hpp"
#include "d2gs/train/densify.hpp"
#include "d2gs/train/kernels/optim.hpp"
#include "test_paths.hpp"

namespace d2gs::test {
namespace {

namespace emulate = render::kernels::emulate;
namespace tk = train_kernels;

struct Case {
  Gaussians model;
  AdamState adam;
  GradientStats stats;
  Rng rng;
};

// n Gaussians of SH degree `degree`: log scales in [-7, -3.5] (extent 1: percent_dense 0.01 clones
// about a third), opacity logits in [-7, 4] (min_opacity 0.005 ≈ logit -5.3 prunes some), gradient
// means around the threshold, a fifth never visible; the stream holds a spare when `spare`.
Case random_case(std::size_t n, int degree, std::uint64_t seed, bool spare) {
  std::mt19937 gen(static_cast<std::uint32_t>(seed));
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  Case c;
  c.model.resize(n, degree);
  for (auto& v : c.model.means) v = 3.0f * u(gen);
  for (auto& v : c.model.log_scales) v = -7.0f + 1.75f * (u(gen) + 1.0f);
  for (auto& v : c.model.quats) v = u(gen);
  for (auto& v : c.model.opacity_logits) v = -1.5f + 5.5f * u(gen);
  for (auto& v : c.model.sh_dc) v = u(gen);
  for (auto& v : c.model.sh_rest) v = 0.1f * u(gen);
  c.adam = Adam::make_state(c.model);
  for (Gaussians* m : {&c.adam.exp_avg, &c.adam.exp_avg_sq})
    for (auto* a : {&m->means, &m->log_scales, &m->quats, &m->opacity_logits, &m->sh_dc, &m->sh_rest})
      for (auto& v : *a) v = 1e-3f * u(gen);
  c.adam.step = 123;
  std::vector<float> sums(n), counts(n);
  for (std::size_t i = 0; i < n; ++i) {
    counts[i] = gen() % 5 == 0 ? 0.0f : static_cast<float>(1 + gen() % 7);
    sums[i] = counts[i] * 0.0005f * (1.0f + u(gen));
  }
  c.stats.restore(std::move(sums), std::move(counts));
  c.rng = Rng::stream(seed, "densify");
  c.rng.normal();
  if (!spare) c.rng.normal();
  return c;
}

// tolerance 0: bit for bit; else |a − b| ≤ tolerance·(1 + |b|) (the GPU's expf and log are not glibc's).
float g_tolerance = 0.0f;

bool values_equal(const std::vector<float>& a, const std::vector<float>& b) {
  if (a.size() != b.size()) return false;
  if (g_tolerance == 0.0f) return a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (!(std::fabs(a[i] - b[i]) <= g_tolerance * (1.0f + std::fabs(b[i])))) return false;
  return true;
}

void expect_gaussians_equal(const Gaussians& a, const Gaussians& b, const std::string& what) {
  EXPECT_EQ(a.sh_degree, b.sh_degree) << what;
  EXPECT_TRUE(values_equal(a.means, b.means)) << what << " means";
  EXPECT_TRUE(values_equal(a.log_scales, b.log_scales)) << what << " log_scales";
  EXPECT_TRUE(values_equal(a.quats, b.quats)) << what << " quats";
  EXPECT_TRUE(values_equal(a.opacity_logits, b.opacity_logits)) << what << " opacity";
  EXPECT_TRUE(values_equal(a.sh_dc, b.sh_dc)) << what << " sh_dc";
  EXPECT_TRUE(values_equal(a.sh_rest, b.sh_rest)) << what << " sh_rest";
}

void expect_same(const Case& kernel, const DensifyReport& kr, const Case& cpu, const DensifyReport& cr,
                 const std::string& what) {
  expect_gaussians_equal(kernel.model, cpu.model, what + " model");
  expect_gaussians_equal(kernel.adam.exp_avg, cpu.adam.exp_avg, what + " exp_avg");
  expect_gaussians_equal(kernel.adam.exp_avg_sq, cpu.adam.exp_avg_sq, what + " exp_avg_sq");
  EXPECT_EQ(kernel.adam.step, cpu.adam.step) << what;
  EXPECT_TRUE(values_equal(kernel.stats.sums(), cpu.stats.sums())) << what << " stats";
  EXPECT_TRUE(values_equal(kernel.stats.counts(), cpu.stats.counts())) << what << " stats";
  EXPECT_EQ(kr.cloned, cr.cloned) << what;
  EXPECT_EQ(kr.split, cr.split) << what;
  EXPECT_EQ(kr.pruned, cr.pruned) << what;
  EXPECT_EQ(kr.before, cr.before) << what;
  EXPECT_EQ(kr.after, cr.after) << what;
  EXPECT_EQ(kr.source, cr.source) << what << " source";
  const auto sk = kernel.rng.state(), sc = cpu.rng.state();
  for (int k = 0; k < 4; ++k) EXPECT_EQ(sk.words[k], sc.words[k]) << what << " rng word " << k;
  EXPECT_EQ(sk.has_spare, sc.has_spare) << what << " rng spare held";
  if (g_tolerance == 0.0f)
    EXPECT_EQ(std::memcmp(&sk.spare, &sc.spare, sizeof(double)), 0) << what << " rng spare";
  else
    EXPECT_NEAR(sk.spare, sc.spare, 1e-12 * (1.0 + std::fabs(sc.spare))) << what << " rng spare";
}

using DensifyFn = std::function<DensifyReport(Gaussians&, AdamState&, GradientStats&, float, const DensifyOptions&, Rng&)>;
using PruneFn = std::function<DensifyReport(Gaussians&, AdamState&, GradientStats&, float)>;

// Runs the CPU and the kernel on copies of c; returns the CPU's report (to check the case's intent).
DensifyReport compare(const Case& c, const DensifyOptions& options, const DensifyFn& kernel_fn, const std::string& what,
                      float extent = 1.0f) {
  Case cpu = c, kernel = c;
  const DensifyReport cr = densify_and_prune(cpu.model, cpu.adam, cpu.stats, extent, options, cpu.rng);
  const DensifyReport kr = kernel_fn(kernel.model, kernel.adam, kernel.stats, extent, options, kernel.rng);
  expect_same(kernel, kr, cpu, cr, what);
  return cr;
}

DensifyReport compare_prune(const Case& c, float min_opacity, const PruneFn& kernel_fn, const std::string& what) {
  Case cpu = c, kernel = c;
  const DensifyReport cr = prune_by_opacity(cpu.model, cpu.adam, cpu.stats, min_opacity);
  const DensifyReport kr = kernel_fn(kernel.model, kernel.adam, kernel.stats, min_opacity);
  expect_same(kernel, kr, cpu, cr, what);
  return cr;
}

DensifyFn emulated(emulate::Schedule s) {
  return [s](Gaussians& m, AdamState& a, GradientStats& st, float e, const DensifyOptions& o, Rng& r) {
    return tk::emulated_densify_and_prune(m, a, st, e, o, r, s);
  };
}
PruneFn emulated_prune(emulate::Schedule s) {
  return [s](Gaussians& m, AdamState& a, GradientStats& st, float o) { return tk::emulated_prune_by_opacity(m, a, st, o, s); };
}
DensifyFn device() { return tk::device_densify_and_prune; }
PruneFn device_prune() { return tk::device_prune_by_opacity; }

// The cases of the brief: each asserts its intent on the CPU's report.
void run_cases(const DensifyFn& fn, const PruneFn& prune_fn, const std::string& what) {
  for (std::size_t n : {std::size_t{1}, std::size_t{31}, std::size_t{257}, std::size_t{5000}})
    for (int degree : {0, 3})
      for (bool spare : {false, true}) {
        const std::string at = what + " n " + std::to_string(n) + " degree " + std::to_string(degree) +
                               (spare ? " spare" : "");
        const Case c = random_case(n, degree, n * 7 + static_cast<std::size_t>(degree) + spare, spare);
        DensifyOptions all;  // clone, split and prune
        const auto r = compare(c, all, fn, at + " all");
        if (n >= 257) {
          EXPECT_GT(r.cloned, 0u) << at;
          EXPECT_GT(r.split, 0u) << at;
          EXPECT_GT(r.pruned, 0u) << at;
        }
        DensifyOptions clone_only = all;
        clone_only.percent_dense = 100.0f;
        clone_only.min_opacity = 0.0f;
        const auto rc = compare(c, clone_only, fn, at + " clone only");
        EXPECT_EQ(rc.split + rc.pruned, 0u) << at;
        DensifyOptions split_only = all;
        split_only.percent_dense = 0.0f;
        split_only.min_opacity = 0.0f;
        const auto rs = compare(c, split_only, fn, at + " split only");
        EXPECT_EQ(rs.cloned + rs.pruned, 0u) << at;
        DensifyOptions three = split_only;
        three.split_children = 3;
        compare(c, three, fn, at + " split in 3");
        DensifyOptions prune_only = all;
        prune_only.grad_threshold = 1e30f;
        const auto rp = compare(c, prune_only, fn, at + " prune only");
        EXPECT_EQ(rp.cloned + rp.split, 0u) << at;
        DensifyOptions noop = prune_only;
        noop.min_opacity = 0.0f;
        const auto rn = compare(c, noop, fn, at + " no-op");
        EXPECT_EQ(rn.after, n) << at;
        DensifyOptions empty = all;
        empty.min_opacity = 1.0f;  // every opacity below 1: everything pruned, the normals still drawn
        const auto re = compare(c, empty, fn, at + " empty result");
        EXPECT_EQ(re.after, 0u) << at;
        compare_prune(c, 0.005f, prune_fn, at + " prune_by_opacity");
        compare_prune(c, 1.0f, prune_fn, at + " prune_by_opacity everything");
      }
  const Case none = random_case(0, 1, 1, false);
  compare(none, DensifyOptions{}, fn, what + " n 0");
  compare_prune(none, 0.005f, prune_fn, what + " prune n 0");
}

// reset_opacity against the kernel on copies of c (and of c with infinite and NaN logits): every
// parameter and moment bit for bit (the cap is computed on the host, the rest is a comparison and zeros,
// so the GPU too must agree exactly); some logits must have been capped and some left as they were.
using ResetFn = std::function<void(Gaussians&, AdamState&, float)>;

void compare_reset(const ResetFn& kernel_fn, const std::string& what) {
  for (std::size_t n : {std::size_t{0}, std::size_t{1}, std::size_t{257}, std::size_t{5000}}) {
    Case c = random_case(n, 3, 91 + n, false);
    if (n >= 257) {
      c.model.opacity_logits[3] = INFINITY;
      c.model.opacity_logits[4] = -INFINITY;
      c.model.opacity_logits[5] = NAN;
    }
    for (float ceiling : {0.01f, 0.5f}) {
      const std::string at = what + " n " + std::to_string(n) + " ceiling " + std::to_string(ceiling);
      Case cpu = c, kernel = c;
      reset_opacity(cpu.model, cpu.adam, ceiling);
      kernel_fn(kernel.model, kernel.adam, ceiling);
      expect_gaussians_equal(kernel.model, cpu.model, at + " model");
      expect_gaussians_equal(kernel.adam.exp_avg, cpu.adam.exp_avg, at + " exp_avg");
      expect_gaussians_equal(kernel.adam.exp_avg_sq, cpu.adam.exp_avg_sq, at + " exp_avg_sq");
      if (n < 257) continue;
      std::size_t capped = 0, kept = 0;
      for (std::size_t i = 0; i < n; ++i) {
        capped += kernel.model.opacity_logits[i] != c.model.opacity_logits[i];
        kept += kernel.model.opacity_logits[i] == c.model.opacity_logits[i];
      }
      EXPECT_GT(capped, n / 10) << at;
      EXPECT_GT(kept, n / 10) << at;
      EXPECT_TRUE(std::isnan(kernel.model.opacity_logits[5])) << at;
      EXPECT_EQ(kernel.model.opacity_logits[4], -INFINITY) << at;
      for (std::size_t i = 0; i < n; ++i) EXPECT_EQ(kernel.adam.exp_avg.opacity_logits[i], 0.0f) << at;
    }
  }
}

// Fern's SfM points as the means of a random model (scene extent from its cameras, as the trainer).
Case fern_case(float& extent) {
  SceneLoadOptions load;
  load.resolution = 8;
  const Scene scene = load_scene(shared_data() / "nerf_llff_data/fern", load);
  Case c = random_case(scene.sfm_points.size(), 3, 2024, true);
  for (std::size_t i = 0; i < c.model.size(); ++i)
    for (int k = 0; k < 3; ++k) c.model.means[3 * i + static_cast<std::size_t>(k)] = scene.sfm_points.positions[i][k];
  extent = 1.0f;
  return c;
}

TEST(EmulatedDensify, EqualsTheCpuBitForBit) {
  for (auto s : emulate::kAllSchedules) run_cases(emulated(s), emulated_prune(s), "schedule " + std::to_string(static_cast<int>(s)));
}

TEST(EmulatedDensify, FernSizedEqualsTheCpuBitForBit) {
  float extent = 1.0f;
  const Case c = fern_case(extent);
  ASSERT_GT(c.model.size(), 1000u);
  DensifyOptions options;
  options.percent_dense = 0.01f;
  const auto r = compare(c, options, emulated(emulate::Schedule::Forward), "fern", extent);
  EXPECT_GT(r.cloned, 0u);
  EXPECT_GT(r.split, 0u);
  EXPECT_GT(r.pruned, 0u);
  // Several densifications in a row: the stream continues where the CPU's does.
  Case cpu = c, kernel = c;
  for (int round = 0; round < 3; ++round) {
    const auto cr = densify_and_prune(cpu.model, cpu.adam, cpu.stats, extent, options, cpu.rng);
    const auto kr = tk::emulated_densify_and_prune(kernel.model, kernel.adam, kernel.stats, extent, options, kernel.rng);
    expect_same(kernel, kr, cpu, cr, "fern round " + std::to_string(round));
    std::vector<float> sums(cpu.model.size(), 0.002f), counts(cpu.model.size(), 2.0f);
    for (std::size_t i = 0; i < sums.size(); i += 3) sums[i] = 0.0001f;
    cpu.stats.restore(sums, counts);
    kernel.stats.restore(sums, counts);
  }
}

TEST(EmulatedDensify, OpacityResetEqualsTheCpuBitForBit) {
  for (auto s : emulate::kAllSchedules)
    compare_reset([s](Gaussians& m, AdamState& a, float ceiling) { tk::emulated_reset_opacity(m, a, ceiling, s); },
                  "schedule " + std::to_string(static_cast<int>(s)));
}

// On the GPU: the same rows, sources, counts and stream words; values within float rounding.
constexpr float kDeviceTolerance = 1e-6f;

TEST(DeviceDensify, EqualsTheCpuWithinRounding) {
  if (cuda::device_count() == 0) {
    Case c = random_case(10, 0, 1, false);
    EXPECT_THROW(tk::device_densify_and_prune(c.model, c.adam, c.stats, 1.0f, DensifyOptions{}, c.rng), Error);
    GTEST_SKIP() << cuda::describe_device();
  }
  g_tolerance = kDeviceTolerance;
  run_cases(device(), device_prune(), "device");
  g_tolerance = 0.0f;
}

TEST(DeviceDensify, OpacityResetEqualsTheCpuBitForBit) {
  if (cuda::device_count() == 0) {
    Case c = random_case(10, 0, 1, false);
    EXPECT_THROW(tk::device_reset_opacity(c.model, c.adam), Error);
    GTEST_SKIP() << cuda::describe_device();
  }
  compare_reset([](Gaussians& m, AdamState& a, float ceiling) { tk::device_reset_opacity(m, a, ceiling); }, "device");
}

TEST(DeviceDensify, FernSizedEqualsTheCpuWithinRounding) {
  if (cuda::device_count() == 0) GTEST_SKIP() << cuda::describe_device();
  float extent = 1.0f;
  const Case c = fern_case(extent);
  g_tolerance = kDeviceTolerance;
  compare(c, DensifyOptions{}, device(), "fern", extent);
  g_tolerance = 0.0f;
}

}  // namespace
}  // namespace d2gs::test
