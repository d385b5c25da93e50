// The alpha-compositing kernels (render/kernels/composite_kernels.hpp) against the CPU reference
// (cpu::composite_forward / composite_backward on the CPU stages' binning): through the emulator on every
// machine, on the GPU when there is one.
//
// Forward: bit for bit. Each pixel is one thread running composite_math.hpp's per-pixel arithmetic, the
// CPU tile loops' lane arithmetic, with fused multiply-adds exactly where the CPU level in use has them
// (the SSE2 baseline has none; x86-64-v3/v4 and the GPU fuse), and compositing has no sum across pixels.
//
// Backward: every pixel's terms and state are the CPU's bit for bit too, but the sums over pixels and
// tiles run in another order (warp shuffles, then one atomic add per warp, block after block; the CPU sums
// each SIMD lane over its rows, then the lanes pairwise, then a Gaussian's intersections in tile order;
// the CPU's per-lane accumulation is also a fused multiply-add where the kernel rounds each pixel's term
// first). Float sums of the same terms in two orders differ by up to (terms) x 2^-24 x sum |term|, and
// the gradient of a mean or a conic entry cancels between the pixels on either side of the centre, so a
// Gaussian's value can be small next to its terms. Hence the measures, per array: the L2 norm of the
// difference relative to the reference's (<= kBackwardRelL2) and the largest difference relative to the
// largest reference value of the array (<= kBackwardRelMax).
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>

#include "cuda/stage_compare.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/render/cpu/composite.hpp"
#include "d2gs/render/cuda/device.hpp"
#include "d2gs/render/cuda/stages.hpp"
#include "d2gs/render/raster_math.hpp"

namespace d2gs::test {
namespace {

using render::kernels::CompositeGrads;
using render::kernels::CompositeOptions;
using render::kernels::CompositeStages;
using render::kernels::StageOptions;
using render::kernels::StageRunner;
namespace emulate = render::kernels::emulate;

constexpr double kBackwardRelL2 = 1e-5;
constexpr double kBackwardRelMax = 1e-5;
constexpr double kModelRelL2 = 1e-4;  // after the projection and SH backward (same sums, then per-Gaussian maps)

// The CPU tile level in use, restored at the end of a scope that selects others.
class IsaScope {
public:
  IsaScope() : saved_(render::cpu::tile_kernels_float().isa) {}
  ~IsaScope() { render::cpu::select_tile_isa(saved_); }
  IsaScope(const IsaScope&) = delete;
  IsaScope& operator=(const IsaScope&) = delete;

private:
  std::string saved_;
};

// Random dL/d(rgb, alpha, depth) per pixel; an empty vector stands for a null pointer.
struct PixelGrads {
  std::vector<float> rgb, alpha, depth;
  PixelGrads(int width, int height, unsigned seed, bool with_rgb, bool with_alpha, bool with_depth) {
    std::mt19937 rng(seed);
    std::normal_distribution<float> g(0.0f, 1.0f);
    const std::size_t pixels = static_cast<std::size_t>(width) * height;
    if (with_rgb) rgb.resize(pixels * 3);
    if (with_alpha) alpha.resize(pixels);
    if (with_depth) depth.resize(pixels);
    for (auto& v : rgb) v = g(rng);
    for (auto& v : alpha) v = 0.5f * g(rng);
    for (auto& v : depth) v = 0.1f * g(rng);
  }
  const float* r() const { return rgb.empty() ? nullptr : rgb.data(); }
  const float* a() const { return alpha.empty() ? nullptr : alpha.data(); }
  const float* d() const { return depth.empty() ? nullptr : depth.data(); }
};

struct CpuComposite {
  CpuStages stages;
  std::vector<float> rgb, alpha, depth;
  render::cpu::PixelState<float> state;
};

CpuComposite cpu_composite(const render::cpu::ModelView<float>& view, const float* mult,
                           const render::CameraParams<float>& cam, const StageOptions& so, const CompositeOptions& co) {
  CpuComposite c;
  c.stages = cpu_forward(view, mult, cam, so);
  const std::size_t pixels = static_cast<std::size_t>(cam.width) * cam.height;
  c.rgb.resize(pixels * 3);
  c.alpha.resize(pixels);
  c.depth.resize(pixels);
  render::cpu::composite_forward(c.stages.bin, co.background, co.smooth_cutoff, c.rgb.data(), c.alpha.data(),
                                 c.depth.data(), c.state);
  return c;
}

render::cpu::ProjectedGrads<float> cpu_composite_backward(const CpuComposite& c, const CompositeOptions& co,
                                                           const PixelGrads& pg, std::size_t n) {
  render::cpu::ProjectedGrads<float> g;
  std::vector<float> isect;
  render::cpu::composite_backward(c.stages.bin, co.background, co.smooth_cutoff, co.clamp_pass_through, c.state,
                                  pg.r(), pg.a(), pg.d(), n, isect, g);
  return g;
}

// The forward's five outputs bit for bit; returns the number of differing values.
std::size_t expect_forward_bitwise(const CompositeStages& k, const CpuComposite& c, std::size_t pixels,
                                   const std::string& label) {
  EXPECT_EQ(k.rgb.size(), pixels * 3) << label;
  if (k.rgb.size() != pixels * 3) return pixels;
  const Diff rgb = diff(k.rgb.data(), c.rgb.data(), pixels * 3);
  const Diff alpha = diff(k.alpha.data(), c.alpha.data(), pixels);
  const Diff depth = diff(k.depth.data(), c.depth.data(), pixels);
  const Diff t = diff(k.final_transmittance.data(), c.state.final_transmittance.data(), pixels);
  std::size_t contrib = 0;
  for (std::size_t i = 0; i < pixels; ++i) contrib += k.n_contrib[i] != c.state.n_contrib[i];
  EXPECT_EQ(rgb.bit_mismatches, 0u) << label << " rgb, max |diff| " << rgb.max_abs;
  EXPECT_EQ(alpha.bit_mismatches, 0u) << label << " alpha, max |diff| " << alpha.max_abs;
  EXPECT_EQ(depth.bit_mismatches, 0u) << label << " depth, max |diff| " << depth.max_abs;
  EXPECT_EQ(t.bit_mismatches, 0u) << label << " final T, max |diff| " << t.max_abs;
  EXPECT_EQ(contrib, 0u) << label << " last contributors";
  return rgb.bit_mismatches + alpha.bit_mismatches + depth.bit_mismatches + t.bit_mismatches + contrib;
}

// Compositing's gradients against the CPU's; prints the measures.
void expect_grads_close(const CompositeGrads& k, const render::cpu::ProjectedGrads<float>& c, std::size_t n,
                        const std::string& label, double rel_l2 = kBackwardRelL2, double rel_max = kBackwardRelMax) {
  const std::vector<float>* got[] = {&k.mean2d, &k.conic, &k.opacity, &k.color, &k.depth};
  const std::vector<float>* want[] = {&c.mean2d, &c.conic, &c.opacity, &c.color, &c.depth};
  const std::size_t width[] = {2, 3, 1, 3, 1};
  const char* names[] = {"mean2d", "conic", "opacity", "colour", "depth"};
  std::printf("%s: backward rel L2 / rel max", label.c_str());
  for (int a = 0; a < 5; ++a) {
    ASSERT_EQ(got[a]->size(), n * width[a]) << label << " " << names[a];
    const Closeness m = closeness(*got[a], *want[a], n * width[a]);
    EXPECT_LE(m.rel_l2, rel_l2) << label << " " << names[a];
    EXPECT_LE(m.rel_max, rel_max) << label << " " << names[a];
    std::printf(" %s %.2g/%.2g", names[a], m.rel_l2, m.rel_max);
  }
  std::printf("\n");
}

struct Case {
  const char* name;
  int width, height, n;
  unsigned seed;
  double max_opacity;
  bool smooth;
  float background[3];
  bool clamped = false;  // every fifth Gaussian of opacity 0.998: alpha = min(0.99, o G) clamps near its centre
};
const Case kCases[] = {
    {"64x48 N300", 64, 48, 300, 1, 0.6, false, {0, 0, 0}},
    {"61x45 N250 smooth cutoff, background", 61, 45, 250, 2, 0.6, true, {0.2f, 0.5f, 0.9f}},
    {"97x33 N1500 opaque, background", 97, 33, 1500, 4, 0.99, false, {1, 1, 1}},
    {"40x20 N900 smooth cutoff (batches of 256)", 40, 20, 900, 5, 0.3, true, {0, 0, 0}},
    {"48x40 N300 clamped", 48, 40, 300, 6, 0.9, false, {0.5f, 0.5f, 0.5f}, true},
    {"48x40 N300 clamped, smooth cutoff", 48, 40, 300, 7, 0.9, true, {0, 0, 0}, true},
};

TestModel<float> case_model(const Case& c, render::CameraParams<float>& cam) {
  cam = test_camera<float>(c.width, c.height, c.seed);
  auto m = random_model<float>(cam, c.n, c.seed + 100, c.max_opacity);
  if (c.clamped)
    for (std::size_t i = 0; i < m.size(); i += 5) m.opacity_logits[i] = std::log(0.998f / 0.002f);
  return m;
}

StageOptions stage_options(bool smooth) {
  StageOptions o;
  o.active_degree = 3;
  o.alpha_min = smooth ? render::kSmoothAlphaLo : render::kAlphaMin;
  return o;
}

CompositeOptions composite_options(const Case& c, bool pass_through) {
  CompositeOptions o;
  for (int k = 0; k < 3; ++k) o.background[k] = c.background[k];
  o.smooth_cutoff = c.smooth;
  o.clamp_pass_through = pass_through;
  o.fused_multiply_add = cpu_level_fuses();
  return o;
}

// The largest number of Gaussians composited into one pixel, and the longest tile list.
std::pair<int, int> depth_of(const CpuComposite& c) {
  int contrib = 0, list = 0;
  for (int v : c.state.n_contrib) contrib = std::max(contrib, v);
  const auto& bin = c.stages.bin;
  for (int t = 0; t < bin.tiles_x * bin.tiles_y; ++t) list = std::max(list, bin.tile_offsets[t + 1] - bin.tile_offsets[t]);
  return {contrib, list};
}

// Forward and backward of one case through one runner; the forward at every CPU level this machine runs.
void run_case(StageRunner& runner, const Case& c, bool pass_through, const PixelGrads& pg, const std::string& label_in) {
  const std::string label = std::string(c.name) + (pass_through ? ", clamp pass-through" : "") + label_in + " [" +
                            runner.name() + "]";
  render::CameraParams<float> cam;
  const auto m = case_model(c, cam);
  const auto view = m.view();
  const StageOptions so = stage_options(c.smooth);
  const std::size_t pixels = static_cast<std::size_t>(c.width) * c.height, n = m.size();
  IsaScope scope;
  for (const std::string& isa : render::cpu::available_tile_isas()) {
    render::cpu::select_tile_isa(isa);
    const CompositeOptions co = composite_options(c, pass_through);
    const CpuComposite cpu = cpu_composite(view, m.multiplier.data(), cam, so, co);
    runner.forward(view, m.multiplier.data(), cam, so);
    const CompositeStages& k = runner.composite(co);
    expect_forward_bitwise(k, cpu, pixels, label + " " + isa);
    const auto [contrib, list] = depth_of(cpu);
    std::printf("%s %s: forward bit for bit (intersections %zu, longest tile list %d, most composited %d)\n",
                label.c_str(), isa.c_str(), cpu.stages.bin.intersections, list, contrib);
    const CompositeGrads& kg = runner.composite_backward(pg.r(), pg.a(), pg.d());
    expect_grads_close(kg, cpu_composite_backward(cpu, co, pg, n), n, label + " " + isa);
  }
}

TEST(EmulatedComposite, RandomScenesEqualTheCpu) {
  for (auto schedule : {emulate::Schedule::Forward, emulate::Schedule::Reverse}) {
    auto runner = render::kernels::make_emulated_stages(schedule);
    for (const Case& c : kCases)
      for (bool pass_through : {false, true}) {
        const PixelGrads pg(c.width, c.height, c.seed + 7, true, true, true);
        run_case(*runner, c, pass_through, pg, "");
      }
  }
}

TEST(EmulatedComposite, GradientInputsMayBeNull) {
  auto runner = render::kernels::make_emulated_stages();
  const Case& c = kCases[1];
  for (int mask = 0; mask < 8; ++mask) {
    const PixelGrads pg(c.width, c.height, 40 + mask, mask & 1, mask & 2, mask & 4);
    run_case(*runner, c, false, pg, ", d_rgb/d_alpha/d_depth given: " + std::to_string(mask & 1) + std::to_string((mask >> 1) & 1) + std::to_string((mask >> 2) & 1));
  }
}

// The clamped cases do exercise both rules: the CPU's gradients differ between them.
TEST(EmulatedComposite, ClampedCasesTellTheTwoClampGradientRulesApart) {
  for (const Case& c : kCases) {
    if (!c.clamped) continue;
    render::CameraParams<float> cam;
    const auto m = case_model(c, cam);
    const PixelGrads pg(c.width, c.height, c.seed + 7, true, true, true);
    const CompositeOptions exact = composite_options(c, false), passes = composite_options(c, true);
    const CpuComposite cpu = cpu_composite(m.view(), m.multiplier.data(), cam, stage_options(c.smooth), exact);
    const auto a = cpu_composite_backward(cpu, exact, pg, m.size());
    const auto b = cpu_composite_backward(cpu, passes, pg, m.size());
    EXPECT_GT(closeness(b.opacity, a.opacity, m.size()).rel_l2, 1e-3) << c.name;
    EXPECT_GT(closeness(b.mean2d, a.mean2d, m.size() * 2).rel_l2, 1e-3) << c.name;
  }
}

// Each thread reads its own view of shared memory, merged at barriers: a missing __syncthreads() around
// the batches reads stale (poisoned) Gaussians. Tiles of more than 256 Gaussians (several batches).
TEST(EmulatedComposite, SharedMemoryBatchesAreSynchronised) {
  auto runner = render::kernels::make_emulated_stages(emulate::Schedule::SyncVisibility);
  const Case small[] = {
      {"32x16 N700 smooth cutoff", 32, 16, 700, 8, 0.3, true, {0.1f, 0.2f, 0.3f}},
      {"32x16 N400 hard cutoff", 32, 16, 400, 9, 0.3, false, {0, 0, 0}},
  };
  for (const Case& c : small) {
    const PixelGrads pg(c.width, c.height, c.seed, true, true, true);
    run_case(*runner, c, false, pg, "");
  }
}

// Compositing on given inputs (what the GPU tests use) is compositing after the device stages.
TEST(EmulatedComposite, LoadedInputsGiveTheSameAsTheStages) {
  auto runner = render::kernels::make_emulated_stages();
  const Case& c = kCases[0];
  render::CameraParams<float> cam;
  const auto m = case_model(c, cam);
  const CompositeOptions co = composite_options(c, false);
  const StageOptions so = stage_options(false);
  const auto f = runner->forward(m.view(), m.multiplier.data(), cam, so);  // a copy
  const CompositeStages chained = runner->composite(co);
  render::kernels::ProjectedIn in;
  in.width = cam.width;
  in.height = cam.height;
  in.n = m.size();
  in.mean2d = f.mean2d.data();
  in.conic = f.conic.data();
  in.depth = f.depth.data();
  in.opacity = f.opacity.data();
  in.color = f.color.data();
  in.intersections = f.isect_gaussians.size();
  in.isect_gaussians = f.isect_gaussians.data();
  in.tile_ranges = f.tile_ranges.data();
  auto other = render::kernels::make_emulated_stages();
  other->load_projected(in);
  const CompositeStages& loaded = other->composite(co);
  EXPECT_EQ(loaded.rgb, chained.rgb);
  EXPECT_EQ(loaded.n_contrib, chained.n_contrib);
  EXPECT_THROW(other->backward_from_composite(), Error);  // no model behind loaded inputs
}

// Timing mode (bench/bench_cuda.cpp) copies nothing back and keeps the uploaded model while its arrays are
// the same ones; once it is off, the copies show what the device computed in the meantime.
TEST(EmulatedComposite, TimingModeKeepsTheModelOnTheDeviceAndCopiesNothingBack) {
  const Case& c = kCases[0];
  render::CameraParams<float> cam;
  const auto m = case_model(c, cam);
  auto changed = m;
  for (auto& v : changed.sh_dc) v += 0.25f;
  const CompositeOptions co = composite_options(c, false);
  const StageOptions so = stage_options(false);
  const PixelGrads pg(c.width, c.height, c.seed, true, false, false);
  struct Result {
    CompositeStages image;
    render::kernels::BackwardStages grads;
  };
  const auto reference = [&](const TestModel<float>& model) {
    auto r = render::kernels::make_emulated_stages();
    r->forward(model.view(), model.multiplier.data(), cam, so);
    Result out{r->composite(co), {}};
    r->composite_backward(pg.r(), nullptr, nullptr);
    out.grads = r->backward_from_composite();
    return out;
  };
  const Result want_m = reference(m), want_changed = reference(changed);
  ASSERT_NE(want_m.image.rgb, want_changed.image.rgb);

  auto runner = render::kernels::make_emulated_stages();
  auto work = m;  // the model whose values change in place
  runner->forward(work.view(), work.multiplier.data(), cam, so);
  EXPECT_EQ(runner->composite(co).rgb, want_m.image.rgb);
  runner->set_timing_mode(true);
  // Other arrays: uploaded. Nothing is copied back.
  runner->forward(changed.view(), changed.multiplier.data(), cam, so);
  EXPECT_EQ(runner->composite(co).rgb, want_m.image.rgb);
  runner->composite_backward(pg.r(), nullptr, nullptr);
  runner->backward_from_composite();
  runner->synchronize();
  runner->set_timing_mode(false);
  EXPECT_EQ(runner->composite(co).rgb, want_changed.image.rgb);
  runner->composite_backward(pg.r(), nullptr, nullptr);
  EXPECT_EQ(runner->backward_from_composite().sh_dc, want_changed.grads.sh_dc);

  // The same arrays, changed in place: timing mode keeps the model it uploaded first.
  runner->set_timing_mode(true);
  runner->forward(work.view(), work.multiplier.data(), cam, so);
  std::copy(changed.sh_dc.begin(), changed.sh_dc.end(), work.sh_dc.begin());  // in place
  runner->forward(work.view(), work.multiplier.data(), cam, so);
  runner->set_timing_mode(false);
  EXPECT_EQ(runner->composite(co).rgb, want_m.image.rgb);
  runner->forward(work.view(), work.multiplier.data(), cam, so);
  EXPECT_EQ(runner->composite(co).rgb, want_changed.image.rgb);
}

// The whole backward on the device: compositing's gradients go on to the projection and SH kernels
// without a host round trip, and land near the CPU's model gradients.
void expect_chain(StageRunner& runner, const TestModel<float>& m, const float* mult,
                  const render::CameraParams<float>& cam, const StageOptions& so, const CompositeOptions& co,
                  const PixelGrads& pg, const std::string& label) {
  const auto view = m.view();
  const std::size_t n = m.size(), pixels = static_cast<std::size_t>(cam.width) * cam.height;
  const CpuComposite cpu = cpu_composite(view, mult, cam, so, co);
  const auto t0 = std::chrono::steady_clock::now();
  runner.forward(view, mult, cam, so);
  const CompositeStages& k = runner.composite(co);
  const auto t1 = std::chrono::steady_clock::now();
  expect_forward_bitwise(k, cpu, pixels, label);
  const CompositeGrads& kg = runner.composite_backward(pg.r(), pg.a(), pg.d());
  const auto t2 = std::chrono::steady_clock::now();
  const auto cg = cpu_composite_backward(cpu, co, pg, n);
  expect_grads_close(kg, cg, n, label);
  const auto& b = runner.backward_from_composite();
  TestGrads<float> ref;
  ref.resize(m);
  render::cpu::project_backward(view, mult, cam, cpu.stages.proj, cg, ref.view());
  render::cpu::sh_backward(view, so.active_degree, cam, cpu.stages.proj, cg.color.data(), ref.view());
  const std::vector<const std::vector<float>*> got = {&b.means, &b.log_scales, &b.quats, &b.opacity_logits,
                                                      &b.sh_dc, &b.sh_rest};
  const auto want = ref.arrays();
  const char* names[] = {"means", "log_scales", "quats", "opacity_logits", "sh_dc", "sh_rest"};
  std::printf("%s: model gradients rel L2", label.c_str());
  for (std::size_t a = 0; a < got.size(); ++a) {
    const Closeness c = closeness(*got[a], *want[a], want[a]->size());
    EXPECT_LE(c.rel_l2, kModelRelL2) << label << " " << names[a];
    std::printf(" %s %.2g", names[a], c.rel_l2);
  }
  const auto [contrib, list] = depth_of(cpu);
  std::printf("\n%s: %zu intersections, longest tile list %d, most composited %d; composite %.2f s, backward %.2f s\n",
              label.c_str(), cpu.stages.bin.intersections, list, contrib,
              std::chrono::duration<double>(t1 - t0).count(), std::chrono::duration<double>(t2 - t1).count());
}

TEST(EmulatedComposite, BackwardChainsIntoTheProjectionKernels) {
  auto runner = render::kernels::make_emulated_stages();
  const Case& c = kCases[2];
  render::CameraParams<float> cam;
  const auto m = case_model(c, cam);
  for (bool pass_through : {false, true}) {
    const PixelGrads pg(c.width, c.height, 3, true, true, true);
    expect_chain(*runner, m, m.multiplier.data(), cam, stage_options(false), composite_options(c, pass_through), pg,
                 std::string("chain ") + c.name + (pass_through ? ", clamp pass-through" : ""));
  }
}

TEST(EmulatedComposite, FernEqualsTheCpu) {
  const FernCase fern = load_fern_case();
  auto runner = render::kernels::make_emulated_stages();
  CompositeOptions co;
  co.fused_multiply_add = cpu_level_fuses();
  co.background[0] = co.background[1] = co.background[2] = 1.0f;
  const auto& cam = fern.cameras[0];
  const PixelGrads pg(cam.width, cam.height, 17, true, true, true);
  expect_chain(*runner, fern.model, fern.model.multiplier.data(), cam, stage_options(false), co, pg,
               "fern view 0, " + std::string(render::cpu::tile_kernels_float().isa));
}

// The published 3-view cloud as the trainer initialises it: ~100 000 intersections, pixels that stop
// early and Gaussians past the clamp (the pass-through rule: the clamped random cases).
TEST(EmulatedComposite, FernPublishedCloudEqualsTheCpu) {
  const FernCase fern = load_fern_published_case();
  ASSERT_GT(fern.model.size(), 10000u);
  auto runner = render::kernels::make_emulated_stages();
  const auto& cam = fern.cameras[1];
  const PixelGrads pg(cam.width, cam.height, 18, true, true, true);
  CompositeOptions co;
  co.fused_multiply_add = cpu_level_fuses();
  expect_chain(*runner, fern.model, fern.model.multiplier.data(), cam, stage_options(false), co, pg,
               std::string("fern published cloud, view 1, ") + render::cpu::tile_kernels_float().isa);
}

// ---------------------------------------------------------------------------------------------------
// On the GPU (skipped without one): compositing of the CPU stages' own outputs (load_projected), so that
// the comparison is of compositing alone. The per-pixel arithmetic is the CPU's (fmaf where the CPU level
// fuses; IEEE division; no contraction: -fmad=false; the same exp polynomial, not CUDA's expf), so the
// forward is expected bit for bit; it is asserted within 1e-6 and the mismatches are printed. Backward as
// in emulation (the atomics' order is not even fixed on the GPU).

void expect_gpu_composite(StageRunner& gpu, const TestModel<float>& m, const render::CameraParams<float>& cam,
                          const StageOptions& so, const CompositeOptions& co, const PixelGrads& pg,
                          const std::string& label) {
  const auto view = m.view();
  const std::size_t n = m.size(), pixels = static_cast<std::size_t>(cam.width) * cam.height;
  const CpuComposite cpu = cpu_composite(view, m.multiplier.data(), cam, so, co);
  const auto lists = cpu_tile_lists(cpu.stages.bin);
  std::vector<int> gaussians, ranges;
  for (const auto& l : lists) {
    ranges.push_back(static_cast<int>(gaussians.size()));
    gaussians.insert(gaussians.end(), l.begin(), l.end());
    ranges.push_back(static_cast<int>(gaussians.size()));
  }
  const auto& p = cpu.stages.proj;
  render::kernels::ProjectedIn in;
  in.width = cam.width;
  in.height = cam.height;
  in.n = n;
  in.mean2d = p.mean2d.data();
  in.conic = p.conic.data();
  in.depth = p.depth.data();
  in.opacity = p.opacity.data();
  in.color = p.color.data();
  in.intersections = gaussians.size();
  in.isect_gaussians = gaussians.data();
  in.tile_ranges = ranges.data();
  gpu.load_projected(in);
  const CompositeStages& k = gpu.composite(co);
  const Diff rgb = diff(k.rgb.data(), cpu.rgb.data(), pixels * 3);
  const Diff alpha = diff(k.alpha.data(), cpu.alpha.data(), pixels);
  const Diff depth = diff(k.depth.data(), cpu.depth.data(), pixels);
  const Diff t = diff(k.final_transmittance.data(), cpu.state.final_transmittance.data(), pixels);
  std::size_t contrib = 0;
  for (std::size_t i = 0; i < pixels; ++i) contrib += k.n_contrib[i] != cpu.state.n_contrib[i];
  std::printf("%s [gpu]: forward bit mismatches rgb %zu alpha %zu depth %zu T %zu contributors %zu; max |diff| rgb %g "
              "depth %g\n",
              label.c_str(), rgb.bit_mismatches, alpha.bit_mismatches, depth.bit_mismatches, t.bit_mismatches, contrib,
              rgb.max_abs, depth.max_abs);
  EXPECT_LE(rgb.max_abs, 1e-6) << label;
  EXPECT_LE(alpha.max_abs, 1e-6) << label;
  EXPECT_LE(depth.max_abs, 1e-5) << label;
  EXPECT_LE(contrib, pixels / 1000) << label;
  const CompositeGrads& kg = gpu.composite_backward(pg.r(), pg.a(), pg.d());
  expect_grads_close(kg, cpu_composite_backward(cpu, co, pg, n), n, label + " [gpu]");
}

TEST(DeviceComposite, RandomScenesAndFernEqualTheCpu) {
  if (cuda::device_count() == 0) GTEST_SKIP() << cuda::describe_device();
  auto gpu = cuda::make_device_stages();
  IsaScope scope;
  for (const std::string& isa : render::cpu::available_tile_isas()) {
    render::cpu::select_tile_isa(isa);
    for (const Case& c : kCases)
      for (bool pass_through : {false, true}) {
        render::CameraParams<float> cam;
        const auto m = case_model(c, cam);
        const PixelGrads pg(c.width, c.height, c.seed + 7, true, true, true);
        expect_gpu_composite(*gpu, m, cam, stage_options(c.smooth), composite_options(c, pass_through), pg,
                             std::string(c.name) + (pass_through ? ", pass-through " : " ") + isa);
      }
    CompositeOptions co;
    co.fused_multiply_add = cpu_level_fuses();
    for (const FernCase& fern : {load_fern_case(), load_fern_published_case()})
      for (std::size_t v = 0; v < fern.cameras.size(); ++v) {
        const auto& cam = fern.cameras[v];
        const PixelGrads pg(cam.width, cam.height, 17, true, true, true);
        for (bool pass_through : {false, true}) {
          co.clamp_pass_through = pass_through;
          expect_gpu_composite(*gpu, fern.model, cam, stage_options(false), co, pg,
                               "fern (" + std::to_string(fern.model.size()) + " Gaussians) view " + std::to_string(v) +
                                   (pass_through ? " pass-through " : " ") + isa);
        }
      }
  }
}

}  // namespace
}  // namespace d2gs::test
