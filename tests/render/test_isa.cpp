// The compositing tile loops exist once per x86-64 level (render/cpu/composite_tiles.hpp). Every level
// this CPU runs must agree with the double-precision reference, and be bit-identical across thread
// counts on its own.
#include <omp.h>

#include <cmath>
#include <cstring>
#include <string>

#include <gtest/gtest.h>

#include "d2gs/core/error.hpp"
#include "d2gs/render/cpu/composite_tiles.hpp"
#include "render_test_util.hpp"

namespace d2gs::test {
namespace {

// Restores the default level when a test ends.
struct IsaGuard {
  ~IsaGuard() { render::cpu::select_tile_isa(render::cpu::available_tile_isas().back()); }
};

struct FloatRun {
  std::vector<float> rgb, alpha, depth;
  TestGrads<float> grads;
};

FloatRun run_float(const TestModel<float>& m, const render::CameraParams<float>& cam) {
  render::cpu::CpuRasterizerCore<float> core;
  render::RenderOptions options;
  options.background = {0.1f, 0.2f, 0.3f};
  const auto& out = core.forward(m.view(), m.multiplier.data(), cam, options);
  FloatRun r{out.rgb, out.alpha, out.depth, {}};
  const std::size_t pixels = out.alpha.size();
  std::vector<float> w(pixels * 5);
  for (std::size_t i = 0; i < w.size(); ++i) w[i] = std::cos(float(i) * 0.11f);
  r.grads.resize(m);
  core.backward(w.data(), w.data() + pixels * 3, w.data() + pixels * 4, r.grads.view(), r.grads.mean2d_ndc.data());
  return r;
}

TEST(RenderIsa, BaselineIsAlwaysAvailableAndUnknownLevelsAreRejected) {
  IsaGuard guard;
  const auto isas = render::cpu::available_tile_isas();
  ASSERT_FALSE(isas.empty());
  EXPECT_EQ(isas.front(), "baseline");
  EXPECT_THROW(render::cpu::select_tile_isa("sse9"), Error);
  for (const auto& isa : isas) {
    render::cpu::select_tile_isa(isa);
    EXPECT_EQ(std::string(render::cpu::tile_kernels_float().isa), isa);
  }
}

// Each level against the double-precision reference (forward images and every gradient array).
TEST(RenderIsa, EveryLevelMatchesDoubleReference) {
  IsaGuard guard;
  const auto camd = test_camera<double>(96, 64, 8);
  const auto md = random_model(camd, 400, 9, 0.9);
  const auto mf = md.cast<float>();
  const auto camf = test_camera<float>(96, 64, 8);
  render::cpu::CpuRasterizerCore<double> cd;
  render::RenderOptions options;
  options.background = {0.1f, 0.2f, 0.3f};
  const auto& od = cd.forward(md.view(), md.multiplier.data(), camd, options);
  const std::size_t pixels = od.alpha.size();
  std::vector<double> wd(pixels * 5);
  for (std::size_t i = 0; i < wd.size(); ++i) wd[i] = std::cos(double(float(i) * 0.11f));
  TestGrads<double> gd;
  gd.resize(md);
  cd.backward(wd.data(), wd.data() + pixels * 3, wd.data() + pixels * 4, gd.view(), gd.mean2d_ndc.data());
  for (const auto& isa : render::cpu::available_tile_isas()) {
    SCOPED_TRACE(isa);
    render::cpu::select_tile_isa(isa);
    FloatRun f = run_float(mf, camf);
    expect_image_close_to_double(f.rgb, od.rgb);
    EXPECT_LT(rel_l2(f.depth, od.depth), 1e-4);
    auto af = f.grads.arrays();
    auto ad = gd.arrays();
    for (std::size_t a = 0; a < af.size(); ++a) EXPECT_LT(rel_l2(*af[a], *ad[a]), 1e-3) << "array " << a;
    EXPECT_LT(rel_l2(f.grads.mean2d_ndc, gd.mean2d_ndc), 1e-3);
  }
}

TEST(RenderIsa, EveryLevelIsBitIdenticalAcrossThreadCounts) {
  IsaGuard guard;
  const auto cam = test_camera<float>(200, 150, 3);
  const auto m = random_model(cam, 6000, 4, 0.99);
  const int previous = omp_get_max_threads();
  for (const auto& isa : render::cpu::available_tile_isas()) {
    SCOPED_TRACE(isa);
    render::cpu::select_tile_isa(isa);
    omp_set_num_threads(1);
    const FloatRun ref = run_float(m, cam);
    for (int threads : {2, 3}) {
      omp_set_num_threads(threads);
      const FloatRun r = run_float(m, cam);
      EXPECT_EQ(0, std::memcmp(r.rgb.data(), ref.rgb.data(), ref.rgb.size() * sizeof(float)));
      EXPECT_EQ(0, std::memcmp(r.depth.data(), ref.depth.data(), ref.depth.size() * sizeof(float)));
      auto a = const_cast<TestGrads<float>&>(r.grads).arrays();
      auto b = const_cast<TestGrads<float>&>(ref.grads).arrays();
      for (std::size_t k = 0; k < a.size(); ++k)
        EXPECT_EQ(0, std::memcmp(a[k]->data(), b[k]->data(), b[k]->size() * sizeof(float))) << "array " << k;
    }
  }
  omp_set_num_threads(previous);
}

}  // namespace
}  // namespace d2gs::test
