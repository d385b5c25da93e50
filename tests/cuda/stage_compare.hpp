#pragma once
// Runs the CPU reference backend's stage functions and a kernel StageRunner (emulated or GPU) on the same
// scene and measures how far every output lies from the reference.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "d2gs/render/cpu/binning.hpp"
#include "d2gs/render/cpu/composite_tiles.hpp"
#include "d2gs/render/cpu/projection.hpp"
#include "d2gs/render/cpu/sh.hpp"
#include "d2gs/model/gaussians.hpp"
#include "d2gs/render/kernels/stages.hpp"
#include "render/render_test_util.hpp"

namespace d2gs::test {

struct CpuStages {
  render::cpu::Projected<float> proj;
  render::cpu::Binning<float> bin;
};

inline CpuStages cpu_forward(const render::cpu::ModelView<float>& model, const float* multiplier,
                             const render::CameraParams<float>& cam, const render::kernels::StageOptions& options) {
  CpuStages s;
  render::cpu::project_forward(model, multiplier, cam, s.proj);
  render::cpu::sh_forward(model, options.active_degree, cam, s.proj);
  render::cpu::bin_gaussians(s.proj, cam.width, cam.height, options.alpha_min, s.bin);
  return s;
}

// Every tile's Gaussians, front to back.
inline std::vector<std::vector<int>> cpu_tile_lists(const render::cpu::Binning<float>& bin) {
  std::vector<std::vector<int>> lists(static_cast<std::size_t>(bin.tiles_x) * bin.tiles_y);
  for (std::size_t t = 0; t < lists.size(); ++t)
    for (int pos = bin.tile_offsets[t]; pos < bin.tile_offsets[t + 1]; ++pos)
      lists[t].push_back(bin.rank_gaussian[bin.isect_rank[pos]]);
  return lists;
}
inline std::vector<std::vector<int>> kernel_tile_lists(const render::kernels::ForwardStages& f) {
  std::vector<std::vector<int>> lists(static_cast<std::size_t>(f.tiles_x) * f.tiles_y);
  for (std::size_t t = 0; t < lists.size(); ++t)
    for (int j = f.tile_ranges[t * 2]; j < f.tile_ranges[t * 2 + 1]; ++j) lists[t].push_back(f.isect_gaussians[j]);
  return lists;
}

// Number of entries whose bits differ, and the largest absolute difference (NaN counts as a mismatch).
struct Diff {
  std::size_t bit_mismatches = 0;
  double max_abs = 0;
};
inline Diff diff(const float* a, const float* b, std::size_t n) {
  Diff d;
  for (std::size_t i = 0; i < n; ++i) {
    if (std::memcmp(&a[i], &b[i], sizeof(float)) != 0) ++d.bit_mismatches;
    const double e = std::abs(double(a[i]) - double(b[i]));
    d.max_abs = std::max(d.max_abs, std::isnan(e) ? INFINITY : e);
  }
  return d;
}

// Whether two float arrays hold the same bits.
inline bool bit_equal(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0);
}
// Every array of two models (or of two Adam moments) bit for bit.
inline void expect_bit_equal(const Gaussians& a, const Gaussians& b, const std::string& what) {
  EXPECT_EQ(a.size(), b.size()) << what;
  EXPECT_TRUE(bit_equal(a.means, b.means)) << what << " means";
  EXPECT_TRUE(bit_equal(a.log_scales, b.log_scales)) << what << " log_scales";
  EXPECT_TRUE(bit_equal(a.quats, b.quats)) << what << " quats";
  EXPECT_TRUE(bit_equal(a.opacity_logits, b.opacity_logits)) << what << " opacity_logits";
  EXPECT_TRUE(bit_equal(a.sh_dc, b.sh_dc)) << what << " sh_dc";
  EXPECT_TRUE(bit_equal(a.sh_rest, b.sh_rest)) << what << " sh_rest";
}

// Whether the CPU tile loops in use fuse their multiply-adds (x86-64-v3 and above do; the SSE2 baseline does not).
inline bool cpu_level_fuses() { return std::string(render::cpu::tile_kernels_float().isa) != "baseline"; }

// How far `got` lies from `want` over n values: the L2 norm of the difference relative to want's, and the
// largest difference relative to want's largest value (NaN counts as infinitely far).
struct Closeness {
  double rel_l2 = 0, rel_max = 0;
};
inline Closeness closeness(const std::vector<float>& got, const std::vector<float>& want, std::size_t n) {
  double num = 0, den = 0, max_diff = 0, max_ref = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const double w = want[i], e = double(got[i]) - w;
    num += e * e;
    den += w * w;
    max_diff = std::max(max_diff, std::isnan(e) ? INFINITY : std::abs(e));
    max_ref = std::max(max_ref, std::abs(w));
  }
  Closeness c;
  c.rel_l2 = den > 0 ? std::sqrt(num / den) : (num > 0 ? INFINITY : 0.0);
  c.rel_max = max_ref > 0 ? max_diff / max_ref : (max_diff > 0 ? INFINITY : 0.0);
  return c;
}

// Random dL/d(projected quantities), as compositing's backward would hand them over.
struct RandomProjectedGrads {
  std::vector<float> mean2d, conic, depth, opacity, color;
  RandomProjectedGrads(std::size_t n, unsigned seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<float> g(0.0f, 1.0f);
    auto fill = [&](std::vector<float>& v, std::size_t size, float scale) {
      v.resize(size);
      for (auto& x : v) x = scale * g(rng);
    };
    fill(mean2d, n * 2, 1e-2f);
    fill(conic, n * 3, 1.0f);
    fill(depth, n, 1e-2f);
    fill(opacity, n, 1e-1f);
    fill(color, n * 3, 1e-1f);
  }
  render::kernels::ProjectedGradsIn in() const {
    return {mean2d.data(), conic.data(), depth.data(), opacity.data(), color.data()};
  }
  render::cpu::ProjectedGrads<float> cpu() const {
    render::cpu::ProjectedGrads<float> p;
    p.mean2d = mean2d;
    p.conic = conic;
    p.depth = depth;
    p.opacity = opacity;
    p.color = color;
    return p;
  }
};

// A model made from fern's SfM points (shared data), with random shapes, opacities and SH, and a
// DropGaussian-like multiplier (zeros and 1/(1 - r) compensation); and fern's cameras at 1/8 resolution.
struct FernCase {
  TestModel<float> model;
  std::vector<render::CameraParams<float>> cameras;
};
FernCase load_fern_case();
// The same cameras with the published 3-view fused cloud (published_init/fern/3_views_fused.ply) made
// into Gaussians as the trainer's init does (gaussians_from_point_cloud), its scales jittered, random
// opacities (a tenth past the 0.99 clamp), the same multiplier.
FernCase load_fern_published_case();

}  // namespace d2gs::test
