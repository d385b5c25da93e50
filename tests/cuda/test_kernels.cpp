// The CUDA backend's kernels (render/kernels/) against the CPU reference backend's stage functions:
// through the CPU emulator on every machine (bit for bit: the same float operations in the same order,
// both compiled by the host compiler), and on the GPU when there is one (within float tolerances: nvcc
// contracts multiply-adds into FMAs and CUDA's expf/logf/sqrtf round differently).
#include <gtest/gtest.h>

#include <cstdio>
#include <numeric>

#include "cuda/stage_compare.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/render/cuda/device.hpp"
#include "d2gs/render/cuda/stages.hpp"
#include "d2gs/render/kernels/emulate.hpp"
#include "d2gs/render/raster_math.hpp"

namespace d2gs::test {
namespace {

using render::kernels::Dim;
using render::kernels::ForwardStages;
using render::kernels::StageOptions;
using render::kernels::StageRunner;
using render::kernels::Thread;
namespace emulate = render::kernels::emulate;

// ---------------------------------------------------------------------------------------------------
// The emulator itself.

struct ShuffleArgs {
  int* up = nullptr;
  int* down = nullptr;
  int* xor_ = nullptr;
};
struct ShuffleKernel {
  struct Shared {};
  template <class Block>
  static void run(Block& b, Shared&, const ShuffleArgs& a) {
    auto v = b.template reg<int>();
    auto r = b.template reg<int>();
    b.threads([&](const Thread& t) { v[t] = 1000 * t.block_x + t.linear(); });
    b.shfl_up(r, v, 3);
    b.threads([&](const Thread& t) { a.up[t.global_x()] = r[t]; });
    b.shfl_down(r, v, 5);
    b.threads([&](const Thread& t) { a.down[t.global_x()] = r[t]; });
    b.shfl_xor(v, v, 6);  // in place: every lane reads before any writes
    b.threads([&](const Thread& t) { a.xor_[t.global_x()] = v[t]; });
  }
};

TEST(KernelEmulator, ShufflesFollowTheirCudaDefinitions) {
  std::vector<int> up(128), down(128), xr(128);
  emulate::launch<ShuffleKernel>(Dim{2, 1}, Dim{64, 1}, ShuffleArgs{up.data(), down.data(), xr.data()});
  for (int i = 0; i < 128; ++i) {
    const int block = i / 64, t = i % 64, lane = t % 32, warp_base = t - lane;
    const auto value = [&](int l) { return 1000 * block + warp_base + l; };
    EXPECT_EQ(up[i], value(lane >= 3 ? lane - 3 : lane)) << i;
    EXPECT_EQ(down[i], value(lane + 5 < 32 ? lane + 5 : lane)) << i;
    EXPECT_EQ(xr[i], value(lane ^ 6)) << i;
  }
}

// Warp 0 has one lane voting, warp 1 none: warp 0 takes the conditional shuffle, warp 1 keeps its value.
// With `split`, the shuffle's condition differs within a warp: refused.
struct VoteArgs {
  bool split = false;
  int* any = nullptr;
  int* down = nullptr;
};
struct VoteKernel {
  struct Shared {};
  template <class Block>
  static void run(Block& b, Shared&, const VoteArgs& a) {
    auto vote = b.template reg<int>();
    auto active = b.template reg<int>();
    auto v = b.template reg<int>();
    auto r = b.template reg<int>();
    b.threads([&](const Thread& t) {
      vote[t] = t.linear() == 7 ? 5 : 0;
      v[t] = t.linear();
      r[t] = -1;
    });
    b.warp_any(active, vote);
    if (a.split) b.threads([&](const Thread& t) { active[t] = t.lane() < 16; });
    b.shfl_down_if(active, r, v, 4);
    b.threads([&](const Thread& t) {
      a.any[t.linear()] = active[t];
      a.down[t.linear()] = r[t];
    });
  }
};

TEST(KernelEmulator, WarpVoteAndAShuffleTakenByWholeWarpsOnly) {
  std::vector<int> any(64), down(64);
  emulate::launch<VoteKernel>(Dim{1, 1}, Dim{64, 1}, VoteArgs{false, any.data(), down.data()});
  for (int i = 0; i < 64; ++i) {
    EXPECT_EQ(any[i], i < 32 ? 1 : 0) << i;
    EXPECT_EQ(down[i], i >= 32 ? -1 : (i % 32) + 4 < 32 ? i + 4 : i) << i;
  }
  EXPECT_THROW(emulate::launch<VoteKernel>(Dim{1, 1}, Dim{64, 1}, VoteArgs{true, any.data(), down.data()}), Error);
}

struct PoisonArgs {
  float* shared_value = nullptr;
  int* register_value = nullptr;
};
struct PoisonKernel {
  struct Shared {
    float values[32];
  };
  template <class Block>
  static void run(Block& b, Shared& sh, const PoisonArgs& a) {
    auto r = b.template reg<int>();
    b.threads([&](const Thread& t) {
      a.shared_value[t.linear()] = sh.values[t.lane()];  // read before any write: garbage on the GPU
      a.register_value[t.linear()] = r[t];
    });
  }
};

TEST(KernelEmulator, PoisonsSharedMemoryAndRegistersAndRejectsPartialWarps) {
  std::vector<float> s(32, 0.0f);
  std::vector<int> r(32, 0);
  emulate::launch<PoisonKernel>(Dim{1, 1}, Dim{32, 1}, PoisonArgs{s.data(), r.data()});
  for (int i = 0; i < 32; ++i) {
    EXPECT_TRUE(std::isnan(s[i])) << i;
    EXPECT_EQ(static_cast<unsigned>(r[i]), 0xa5a5a5a5u) << i;
  }
  EXPECT_THROW(emulate::launch<PoisonKernel>(Dim{1, 1}, Dim{48, 1}, PoisonArgs{s.data(), r.data()}), Error);
}

struct AtomicArgs {
  int* counter = nullptr;
  int* old = nullptr;
};
struct AtomicKernel {
  struct Shared {};
  template <class Block>
  static void run(Block& b, Shared&, const AtomicArgs& a) {
    b.threads([&](const Thread& t) { a.old[t.global_x()] = b.atomic_add(a.counter, 1); });
  }
};

TEST(KernelEmulator, AtomicsAreAddsInThreadOrder) {
  int counter = 0;
  std::vector<int> old(128);
  emulate::launch<AtomicKernel>(Dim{2, 1}, Dim{64, 1}, AtomicArgs{&counter, old.data()});
  EXPECT_EQ(counter, 128);
  for (int i = 0; i < 128; ++i) EXPECT_EQ(old[i], i);
  counter = 0;
  emulate::launch<AtomicKernel>(Dim{2, 1}, Dim{64, 1}, AtomicArgs{&counter, old.data()}, emulate::Schedule::Reverse);
  for (int i = 0; i < 128; ++i) EXPECT_EQ(old[i], 127 - i);
}

// A kernel with a race (thread t reads what thread t + 1 writes in the same phase, without a
// __syncthreads between): the two emulation orders disagree, which is how the order test catches races
// inside a phase.
struct RaceArgs {
  int* out = nullptr;
};
struct RaceKernel {
  struct Shared {
    int values[64];
  };
  template <class Block>
  static void run(Block& b, Shared& sh, const RaceArgs& a) {
    b.threads([&](const Thread& t) { sh.values[t.linear()] = 0; });
    b.sync();
    b.threads([&](const Thread& t) {
      sh.values[t.linear()] = t.linear() + 1;
      a.out[t.linear()] = t.linear() + 1 < 64 ? sh.values[t.linear() + 1] : -1;
    });
  }
};

TEST(KernelEmulator, ThreadOrdersExposeARaceWithinAPhase) {
  std::vector<int> forward(64), reverse(64);
  emulate::launch<RaceKernel>(Dim{1, 1}, Dim{64, 1}, RaceArgs{forward.data()});
  emulate::launch<RaceKernel>(Dim{1, 1}, Dim{64, 1}, RaceArgs{reverse.data()}, emulate::Schedule::Reverse);
  EXPECT_NE(forward, reverse);
}

// Thread t writes its slot, and after the barrier (or, wrongly, without it) reads its neighbour's.
struct NeighbourArgs {
  bool with_sync = true;
  int* out = nullptr;
};
struct NeighbourKernel {
  struct Shared {
    int values[64];
  };
  template <class Block>
  static void run(Block& b, Shared& sh, const NeighbourArgs& a) {
    b.threads([&](const Thread& t) { sh.values[t.linear()] = 10 * t.linear(); });
    if (a.with_sync) b.sync();
    b.threads([&](const Thread& t) { a.out[t.linear()] = sh.values[(t.linear() + 1) % 64]; });
  }
};

TEST(KernelEmulator, SyncVisibilityExposesAMissingSync) {
  std::vector<int> expected(64);
  for (int t = 0; t < 64; ++t) expected[t] = 10 * ((t + 1) % 64);
  for (bool with_sync : {true, false}) {
    std::vector<int> forward(64), visible_at_sync(64);
    emulate::launch<NeighbourKernel>(Dim{1, 1}, Dim{64, 1}, NeighbourArgs{with_sync, forward.data()});
    emulate::launch<NeighbourKernel>(Dim{1, 1}, Dim{64, 1}, NeighbourArgs{with_sync, visible_at_sync.data()},
                                     emulate::Schedule::SyncVisibility);
    EXPECT_EQ(forward, expected);  // the plain schedule cannot tell
    if (with_sync) {
      EXPECT_EQ(visible_at_sync, expected);
    } else {
      EXPECT_EQ(visible_at_sync, std::vector<int>(64, -1));  // the poisoned memory of the last sync
    }
  }
}

struct ConflictArgs {
  int unused = 0;
};
struct ConflictKernel {
  struct Shared {
    int value;
  };
  template <class Block>
  static void run(Block& b, Shared& sh, const ConflictArgs&) {
    b.threads([&](const Thread& t) { sh.value = t.linear(); });
    b.sync();
  }
};

TEST(KernelEmulator, SyncVisibilityReportsTwoThreadsWritingOneByte) {
  EXPECT_NO_THROW(emulate::launch<ConflictKernel>(Dim{1, 1}, Dim{32, 1}, ConflictArgs{}));
  EXPECT_THROW(emulate::launch<ConflictKernel>(Dim{1, 1}, Dim{32, 1}, ConflictArgs{}, emulate::Schedule::SyncVisibility),
               Error);
}

TEST(KernelEmulator, SortIsStableOnTheKeyBits) {
  const std::vector<std::uint64_t> keys = {(3ull << 32) | 7, (1ull << 32) | 9, (3ull << 32) | 7, (1ull << 32) | 2};
  const std::vector<std::int32_t> values = {0, 1, 2, 3};
  std::vector<std::uint64_t> k(4);
  std::vector<std::int32_t> v(4);
  emulate::sort_pairs(keys.data(), k.data(), values.data(), v.data(), 4, 34);
  EXPECT_EQ(v, (std::vector<std::int32_t>{3, 1, 0, 2}));
  EXPECT_EQ(k[0], (1ull << 32) | 2);
}

// ---------------------------------------------------------------------------------------------------
// The kernels against the CPU reference.

std::vector<std::unique_ptr<StageRunner>> emulated_runners() {
  std::vector<std::unique_ptr<StageRunner>> r;
  for (auto s : {emulate::Schedule::Forward, emulate::Schedule::Reverse, emulate::Schedule::SyncVisibility})
    r.push_back(render::kernels::make_emulated_stages(s));
  return r;
}

void expect_scan(StageRunner& runner) {
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> u(0, 20);
  for (int n : {0, 1, 31, 32, 255, 256, 257, 1000, 65536, 65537, 300001}) {
    std::vector<int> values(static_cast<std::size_t>(n));
    for (auto& v : values) v = u(rng);
    std::vector<int> expected(values.size());
    std::inclusive_scan(values.begin(), values.end(), expected.begin());
    EXPECT_EQ(runner.inclusive_scan(values), expected) << runner.name() << ", n = " << n;
  }
}

TEST(EmulatedKernels, InclusiveScanEqualsStdInclusiveScan) {
  for (auto& runner : emulated_runners()) expect_scan(*runner);
}

// The tile-intersection outputs against the CPU binning of the same projected Gaussians.
void expect_binning_equal(const ForwardStages& f, const render::cpu::Binning<float>& bin, std::size_t n,
                          const std::string& label) {
  ASSERT_EQ(f.rects.size(), n * 4) << label;
  std::size_t rect_mismatches = 0, culled = 0, area = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const int* r = &bin.rect[i * 4];
    rect_mismatches += !std::equal(r, r + 4, &f.rects[i * 4]);
    area += static_cast<std::size_t>((r[2] - r[0]) * (r[3] - r[1]));
  }
  const std::vector<int> counts(bin.tile_count.begin(), bin.tile_count.begin() + static_cast<std::ptrdiff_t>(n));
  for (int c : counts) culled += static_cast<std::size_t>(c);
  culled = area - culled;
  EXPECT_EQ(rect_mismatches, 0u) << label;
  EXPECT_EQ(f.tile_counts, counts) << label;  // the tiles of each rectangle kept (tile_reach_columns)
  std::printf("%s: %zu of %zu rectangle tiles culled\n", label.c_str(), culled, area);
  std::vector<int> offsets(n);
  std::inclusive_scan(counts.begin(), counts.end(), offsets.begin());
  EXPECT_EQ(f.isect_offsets, offsets) << label;
  EXPECT_EQ(f.isect_keys.size(), bin.intersections) << label;
  const auto lists = kernel_tile_lists(f);
  EXPECT_EQ(lists, cpu_tile_lists(bin)) << label;
  // Keys: sorted, their tile is the range they sit in, their low bits the Gaussian's depth.
  EXPECT_TRUE(std::is_sorted(f.isect_keys.begin(), f.isect_keys.end())) << label;
  std::size_t key_errors = 0;
  for (std::size_t t = 0; t < lists.size(); ++t)
    for (int j = f.tile_ranges[t * 2]; j < f.tile_ranges[t * 2 + 1]; ++j) {
      const std::uint64_t key = f.isect_keys[static_cast<std::size_t>(j)];
      const int g = f.isect_gaussians[static_cast<std::size_t>(j)];
      key_errors += (key >> 32) != t || static_cast<std::uint32_t>(key) != render::kernels::float_bits(f.depth[g]);
    }
  EXPECT_EQ(key_errors, 0u) << label;
}

// Emulated kernels against the CPU stages: every output bit for bit.
void expect_bitwise(StageRunner& runner, const TestModel<float>& m, const render::CameraParams<float>& cam,
                    const StageOptions& options, bool use_multiplier, const std::string& label_in) {
  const std::string label = label_in + " [" + runner.name() + "]";
  const auto view = m.view();
  const float* mult = use_multiplier ? m.multiplier.data() : nullptr;
  const std::size_t n = m.size();
  const CpuStages cpu = cpu_forward(view, mult, cam, options);
  const ForwardStages& f = runner.forward(view, mult, cam, options);

  const Diff d_mean2d = diff(f.mean2d.data(), cpu.proj.mean2d.data(), n * 2);
  const Diff d_conic = diff(f.conic.data(), cpu.proj.conic.data(), n * 3);
  const Diff d_depth = diff(f.depth.data(), cpu.proj.depth.data(), n);
  const Diff d_opacity = diff(f.opacity.data(), cpu.proj.opacity.data(), n);
  const Diff d_color = diff(f.color.data(), cpu.proj.color.data(), n * 3);
  EXPECT_EQ(d_mean2d.bit_mismatches, 0u) << label;
  EXPECT_EQ(d_conic.bit_mismatches, 0u) << label;
  EXPECT_EQ(d_depth.bit_mismatches, 0u) << label;
  EXPECT_EQ(d_opacity.bit_mismatches, 0u) << label;
  EXPECT_EQ(d_color.bit_mismatches, 0u) << label;
  EXPECT_TRUE(std::equal(f.radii.begin(), f.radii.end(), cpu.proj.radii.begin())) << label;
  EXPECT_TRUE(std::equal(f.color_clamped.begin(), f.color_clamped.end(), cpu.proj.color_clamped.begin())) << label;
  expect_binning_equal(f, cpu.bin, n, label);

  // Backward from random gradients of the projected quantities.
  const RandomProjectedGrads g(n, 11);
  TestGrads<float> ref;
  ref.resize(m);
  render::cpu::project_backward(view, mult, cam, cpu.proj, g.cpu(), ref.view());
  render::cpu::sh_backward(view, options.active_degree, cam, cpu.proj, g.color.data(), ref.view());
  const auto& b = runner.backward(g.in());
  const std::vector<const std::vector<float>*> got = {&b.means, &b.log_scales, &b.quats, &b.opacity_logits,
                                                      &b.sh_dc, &b.sh_rest};
  const auto want = ref.arrays();
  const char* names[] = {"means", "log_scales", "quats", "opacity_logits", "sh_dc", "sh_rest"};
  std::size_t visible = 0, intersections = f.isect_keys.size();
  for (int r : f.radii) visible += r > 0;
  std::printf("%s: N %zu, visible %zu, intersections %zu; forward max |diff| mean2d %g conic %g depth %g opacity %g"
              " colour %g; backward max |diff|",
              label.c_str(), n, visible, intersections, d_mean2d.max_abs, d_conic.max_abs, d_depth.max_abs,
              d_opacity.max_abs, d_color.max_abs);
  for (std::size_t k = 0; k < got.size(); ++k) {
    ASSERT_EQ(got[k]->size(), want[k]->size()) << label << " " << names[k];
    const Diff d = diff(got[k]->data(), want[k]->data(), got[k]->size());
    EXPECT_EQ(d.bit_mismatches, 0u) << label << " " << names[k] << " max |diff| " << d.max_abs;
    std::printf(" %s %g", names[k], d.max_abs);
  }
  std::printf("\n");
  EXPECT_GT(visible, 0u) << label;
  EXPECT_GT(intersections, 0u) << label;
}

// A copy of a degree-3 model reduced to `degree` (sh_rest truncated per Gaussian).
TestModel<float> with_degree(const TestModel<float>& m, int degree) {
  TestModel<float> r = m;
  r.sh_degree = degree;
  r.sh_rest.clear();
  const int K3 = m.K(), K = r.K();
  for (std::size_t i = 0; i < m.size(); ++i)
    for (int k = 0; k < K * 3; ++k) r.sh_rest.push_back(m.sh_rest[i * K3 * 3 + k]);
  return r;
}

struct RandomCase {
  const char* name;
  int width, height, n;
  unsigned seed;
  int model_degree, active_degree;
  bool multiplier;
  double alpha_min, max_opacity;
};
const RandomCase kRandomCases[] = {
    {"64x48 N300 SH3", 64, 48, 300, 1, 3, 3, true, render::kAlphaMin, 0.6},
    {"61x45 N250 SH3/2 smooth cutoff", 61, 45, 250, 2, 3, 2, false, render::kSmoothAlphaLo, 0.6},
    {"504x378 N20000 SH1 opaque", 504, 378, 20000, 3, 1, 1, true, render::kAlphaMin, 0.99},
    {"97x33 N1000 SH0", 97, 33, 1000, 4, 0, 0, true, render::kAlphaMin, 0.9},
};

TestModel<float> random_case_model(const RandomCase& c, render::CameraParams<float>& cam) {
  cam = test_camera<float>(c.width, c.height, c.seed);
  return with_degree(random_model<float>(cam, c.n, c.seed + 100, c.max_opacity), c.model_degree);
}

TEST(EmulatedKernels, RandomScenesEqualTheCpuStagesBitForBit) {
  for (auto& runner : emulated_runners())
    for (const auto& c : kRandomCases) {
      render::CameraParams<float> cam;
      const auto m = random_case_model(c, cam);
      StageOptions o;
      o.active_degree = c.active_degree;
      o.alpha_min = c.alpha_min;
      expect_bitwise(*runner, m, cam, o, c.multiplier, c.name);
    }
}

// Two small Gaussians, each in one tile of its own (the first and the last touched tile hold a single
// intersection: the ends of the tile ranges).
TEST(EmulatedKernels, TilesOfOneGaussianEach) {
  render::CameraParams<float> cam;
  cam.width = 64;
  cam.height = 48;
  cam.fx = cam.fy = 50.0f;
  cam.cx = 32.0f;
  cam.cy = 24.0f;
  render::set_jacobian_limits(cam);
  TestModel<float> m;
  m.sh_degree = 0;
  m.means = {-0.4f, -0.3f, 1.0f, 0.4f, 0.3f, 1.0f};
  m.log_scales.assign(6, std::log(0.001f));
  m.quats = {1, 0, 0, 0, 1, 0, 0, 0};
  m.opacity_logits = {0.0f, 0.0f};
  m.sh_dc = {0.1f, 0.2f, 0.3f, 0.3f, 0.2f, 0.1f};
  m.multiplier = {1.0f, 1.0f};
  for (auto& runner : emulated_runners()) {
    expect_bitwise(*runner, m, cam, StageOptions{}, false, "two Gaussians");
    const auto& f = runner->forward(m.view(), nullptr, cam, StageOptions{});
    EXPECT_EQ(f.tile_counts, (std::vector<int>{1, 1}));
    EXPECT_EQ(f.tile_ranges, (std::vector<int>{0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,  // tiles 0-5
                                                0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 2}));  // tiles 6-11
    EXPECT_EQ(f.isect_gaussians, (std::vector<int>{0, 1}));
  }
}

// 2 200 Gaussians that each cover the whole of a 16384 x 16384 image (1 048 576 tiles): 2.3e9 (Gaussian, tile)
// pairs, more than the int tile lists index. Both backends refuse the frame with one error (nothing that size
// is allocated first), and the projected radius (3 sigma = 1e8 px) is held at 2^24 rather than converted
// past an int's range.
TEST(EmulatedKernels, AFrameWithMorePairsThanTheTileListsIndexIsRefused) {
  const int side = 16384;
  render::CameraParams<float> cam;
  cam.width = cam.height = side;
  cam.fx = cam.fy = float(side);
  cam.cx = cam.cy = 0.5f * side;
  render::set_jacobian_limits(cam);
  TestModel<float> m;
  m.sh_degree = 0;
  const std::size_t n = 2200;
  for (std::size_t i = 0; i < n; ++i) {
    m.means.insert(m.means.end(), {0.001f * float(i % 7), -0.001f * float(i % 5), 10.0f});
    m.log_scales.insert(m.log_scales.end(), {10.0f, 10.0f, 10.0f});
    m.quats.insert(m.quats.end(), {1.0f, 0.0f, 0.0f, 0.0f});
    m.opacity_logits.push_back(4.0f);
    m.sh_dc.insert(m.sh_dc.end(), {0.1f, 0.2f, 0.3f});
    m.multiplier.push_back(1.0f);
  }
  const StageOptions o;
  render::cpu::Projected<float> proj;
  render::cpu::project_forward<float>(m.view(), nullptr, cam, proj);
  EXPECT_EQ(proj.radii[0], 1 << 24);
  try {
    cpu_forward(m.view(), nullptr, cam, o);
    ADD_FAILURE() << "the CPU binning took the frame";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("(Gaussian, tile) pairs of the 16384x16384 image"), std::string::npos)
        << e.what();
  }
  for (auto& runner : emulated_runners()) {
    try {
      runner->forward(m.view(), nullptr, cam, o);
      ADD_FAILURE() << "the kernels took the frame";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("(Gaussian, tile) pairs"), std::string::npos) << e.what();
    }
  }
}

TEST(EmulatedKernels, EmptyModelGivesEmptyTiles) {
  const auto cam = test_camera<float>(40, 30, 1);
  TestModel<float> m;
  m.sh_degree = 1;
  for (auto& runner : emulated_runners()) {
    const auto& f = runner->forward(m.view(), nullptr, cam, StageOptions{});
    EXPECT_TRUE(f.radii.empty() && f.isect_keys.empty() && f.isect_gaussians.empty());
    EXPECT_EQ(f.tile_ranges, std::vector<int>(3 * 2 * 2, 0));
    const auto& b = runner->backward(render::kernels::ProjectedGradsIn{});
    EXPECT_TRUE(b.means.empty() && b.sh_rest.empty());
  }
}

TEST(EmulatedKernels, FernEqualsTheCpuStagesBitForBit) {
  const FernCase fern = load_fern_case();
  ASSERT_GT(fern.model.size(), 1000u);
  for (auto& runner : emulated_runners())
    for (std::size_t v = 0; v < fern.cameras.size(); ++v) {
      StageOptions o;
      o.active_degree = 3;
      expect_bitwise(*runner, fern.model, fern.cameras[v], o, true, "fern view " + std::to_string(v));
    }
}

// ---------------------------------------------------------------------------------------------------
// The same kernels on a GPU (skipped without one).

TEST(DeviceKernels, RefuseCleanlyWithoutAGpu) {
  if (cuda::device_count() > 0) GTEST_SKIP() << "a GPU is present: " << cuda::describe_device();
  EXPECT_THROW(cuda::make_device_stages(), Error);
}

TEST(DeviceKernels, InclusiveScanEqualsStdInclusiveScan) {
  if (cuda::device_count() == 0) GTEST_SKIP() << cuda::describe_device();
  expect_scan(*cuda::make_device_stages());
}

// GPU against CPU. Tolerances (float32, FMA contraction and CUDA's own expf/logf/sqrtf): projected
// values to 1e-4 relative (mean2d 1e-3 px), colours 1e-5, radii within 1 where both project, at most
// 0.1 % of Gaussians culled by one side only; binning equal to the CPU binning of the GPU's own
// projection except for the Gaussians whose rectangles differ (at most 0.5 %), removed from both lists;
// gradients of Gaussians visible on both sides to 1e-4 relative L2 per array.
void expect_gpu_close(StageRunner& runner, const TestModel<float>& m, const render::CameraParams<float>& cam,
                      const StageOptions& options, bool use_multiplier, const std::string& label) {
  const auto view = m.view();
  const float* mult = use_multiplier ? m.multiplier.data() : nullptr;
  const std::size_t n = m.size();
  const CpuStages cpu = cpu_forward(view, mult, cam, options);
  const ForwardStages& f = runner.forward(view, mult, cam, options);
  std::size_t one_sided = 0, both = 0;
  std::vector<std::uint8_t> compare(n, 0);
  double max_mean2d = 0, max_conic_rel = 0, max_depth_rel = 0, max_opacity = 0, max_color = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const int rc = cpu.proj.radii[i], rg = f.radii[i];
    max_opacity = std::max(max_opacity, double(std::abs(f.opacity[i] - cpu.proj.opacity[i])));
    if ((rc > 0) != (rg > 0)) {
      ++one_sided;
      continue;
    }
    if (rc == 0) continue;
    ++both;
    EXPECT_LE(std::abs(rc - rg), 1) << label << " radius of " << i;
    for (int k = 0; k < 2; ++k)
      max_mean2d = std::max(max_mean2d, double(std::abs(f.mean2d[i * 2 + k] - cpu.proj.mean2d[i * 2 + k])));
    for (int k = 0; k < 3; ++k) {
      const double c = cpu.proj.conic[i * 3 + k];
      max_conic_rel = std::max(max_conic_rel, std::abs(f.conic[i * 3 + k] - c) / (1.0 + std::abs(c)));
    }
    max_depth_rel = std::max(max_depth_rel, double(std::abs(f.depth[i] - cpu.proj.depth[i]) / cpu.proj.depth[i]));
    bool same_clamp = true;
    for (int k = 0; k < 3; ++k) {
      max_color = std::max(max_color, double(std::abs(f.color[i * 3 + k] - cpu.proj.color[i * 3 + k])));
      same_clamp &= f.color_clamped[i * 3 + k] == cpu.proj.color_clamped[i * 3 + k];
    }
    compare[i] = same_clamp;
  }
  EXPECT_LE(one_sided, n / 1000 + 1) << label;
  EXPECT_LE(max_mean2d, 1e-3) << label;
  EXPECT_LE(max_conic_rel, 1e-4) << label;
  EXPECT_LE(max_depth_rel, 1e-5) << label;
  EXPECT_LE(max_opacity, 1e-6) << label;
  EXPECT_LE(max_color, 1e-5) << label;

  // Binning: the CPU binning of the GPU's projection; Gaussians with different rectangles set aside.
  render::cpu::Projected<float> gp;
  gp.resize(n);
  std::copy(f.mean2d.begin(), f.mean2d.end(), gp.mean2d.begin());
  std::copy(f.conic.begin(), f.conic.end(), gp.conic.begin());
  std::copy(f.depth.begin(), f.depth.end(), gp.depth.begin());
  std::copy(f.opacity.begin(), f.opacity.end(), gp.opacity.begin());
  std::copy(f.radii.begin(), f.radii.end(), gp.radii.begin());
  std::copy(f.color.begin(), f.color.end(), gp.color.begin());
  render::cpu::Binning<float> bin;
  render::cpu::bin_gaussians(gp, cam.width, cam.height, options.alpha_min, bin);
  // A Gaussian whose rectangle, or the tiles kept of it, differ (the GPU's rounding near a margin) is set
  // aside.
  std::vector<std::uint8_t> differs(n, 0);
  std::size_t rect_mismatches = 0;
  {
    std::vector<std::vector<int>> cpu_tiles(n), gpu_tiles(n);
    const auto cl = cpu_tile_lists(bin), gl = kernel_tile_lists(f);
    for (std::size_t t = 0; t < cl.size(); ++t) {
      for (int g : cl[t]) cpu_tiles[static_cast<std::size_t>(g)].push_back(static_cast<int>(t));
      for (int g : gl[t]) gpu_tiles[static_cast<std::size_t>(g)].push_back(static_cast<int>(t));
    }
    for (std::size_t i = 0; i < n; ++i) {
      differs[i] = !std::equal(&bin.rect[i * 4], &bin.rect[i * 4] + 4, &f.rects[i * 4]) || cpu_tiles[i] != gpu_tiles[i];
      rect_mismatches += differs[i];
    }
  }
  EXPECT_LE(rect_mismatches, n / 200 + 1) << label;
  auto strip = [&](std::vector<std::vector<int>> lists) {
    for (auto& l : lists) l.erase(std::remove_if(l.begin(), l.end(), [&](int g) { return differs[g] != 0; }), l.end());
    return lists;
  };
  EXPECT_EQ(strip(kernel_tile_lists(f)), strip(cpu_tile_lists(bin))) << label;
  EXPECT_TRUE(std::is_sorted(f.isect_keys.begin(), f.isect_keys.end())) << label;

  // Backward.
  const RandomProjectedGrads g(n, 11);
  TestGrads<float> ref;
  ref.resize(m);
  render::cpu::project_backward(view, mult, cam, cpu.proj, g.cpu(), ref.view());
  render::cpu::sh_backward(view, options.active_degree, cam, cpu.proj, g.color.data(), ref.view());
  const auto& b = runner.backward(g.in());
  const std::vector<const std::vector<float>*> got = {&b.means, &b.log_scales, &b.quats, &b.opacity_logits,
                                                      &b.sh_dc, &b.sh_rest};
  const auto want = ref.arrays();
  const char* names[] = {"means", "log_scales", "quats", "opacity_logits", "sh_dc", "sh_rest"};
  std::printf("%s [gpu]: forward max |diff| mean2d %g, conic rel %g, depth rel %g, opacity %g, colour %g; "
              "%zu culled on one side, %zu rectangles or tile sets differ; backward rel L2",
              label.c_str(), max_mean2d, max_conic_rel, max_depth_rel, max_opacity, max_color, one_sided,
              rect_mismatches);
  for (std::size_t k = 0; k < got.size(); ++k) {
    const std::size_t width = want[k]->size() / n;
    double num = 0, den = 0;
    for (std::size_t i = 0; i < n; ++i) {
      if (!compare[i]) continue;
      for (std::size_t c = 0; c < width; ++c) {
        const double w = (*want[k])[i * width + c], e = (*got[k])[i * width + c] - w;
        num += e * e;
        den += w * w;
      }
    }
    const double rel = std::sqrt(num / std::max(den, 1e-300));
    EXPECT_LE(rel, 1e-4) << label << " " << names[k];
    std::printf(" %s %g", names[k], rel);
  }
  std::printf("\n");
  EXPECT_GT(both, 0u) << label;
}

TEST(DeviceKernels, RandomScenesEqualTheCpuStagesWithinFloatTolerance) {
  if (cuda::device_count() == 0) GTEST_SKIP() << cuda::describe_device();
  auto runner = cuda::make_device_stages();
  for (const auto& c : kRandomCases) {
    render::CameraParams<float> cam;
    const auto m = random_case_model(c, cam);
    StageOptions o;
    o.active_degree = c.active_degree;
    o.alpha_min = c.alpha_min;
    expect_gpu_close(*runner, m, cam, o, c.multiplier, c.name);
  }
}

TEST(DeviceKernels, FernEqualsTheCpuStagesWithinFloatTolerance) {
  if (cuda::device_count() == 0) GTEST_SKIP() << cuda::describe_device();
  const FernCase fern = load_fern_case();
  auto runner = cuda::make_device_stages();
  for (std::size_t v = 0; v < fern.cameras.size(); ++v) {
    StageOptions o;
    o.active_degree = 3;
    expect_gpu_close(*runner, fern.model, fern.cameras[v], o, true, "fern view " + std::to_string(v));
  }
}

}  // namespace
}  // namespace d2gs::test
