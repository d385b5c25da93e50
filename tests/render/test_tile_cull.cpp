// The cull of the tiles of a Gaussian's rectangle that its ellipse misses (raster_math.hpp,
// tile_reach_columns; cpu/binning.cpp): a dropped tile has no row whose chord (the tile loops' test,
// alpha_row_span) meets it and no pixel centre where alpha reaches the cutoff, and renders and gradients
// are bit-identical with and without the cull.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "d2gs/render/cpu/binning.hpp"
#include "d2gs/render/cpu/composite.hpp"
#include "d2gs/render/cpu/projection.hpp"
#include "d2gs/render/cpu/sh.hpp"
#include "d2gs/render/raster_math.hpp"
#include "render_test_util.hpp"

namespace d2gs::test {
namespace {

using render::kTileSize;
using render::cpu::Binning;
using render::cpu::Projected;

// n projected Gaussians over a width x height image: means spread beyond the image, 2D covariances
// R diag(s1^2, s2^2) R^T + 0.3 I with axis ratios up to ~3000 and any angle (the conic inverted in T, as the
// projection does, so its determinant carries the same cancellation), opacities up to 0.99.
template <typename T>
Projected<T> random_projected(std::size_t n, int width, int height, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Projected<T> p;
  p.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const int kind = static_cast<int>(i % 8);
    double mx = -40 + (width + 80) * u(rng), my = -40 + (height + 80) * u(rng);
    double s1 = 0.5 + 40 * u(rng) * u(rng), s2 = 0.1 + 3 * u(rng);
    if (kind == 5) s1 = 100 + 1500 * u(rng);  // long needles
    if (kind == 6) {                          // far off the image, reaching into it
      mx = (u(rng) < 0.5 ? -1 : 1) * (2000 + 20000 * u(rng));
      s1 = std::abs(mx) * (0.3 + 0.5 * u(rng));
    }
    if (kind == 7) s2 = 0;  // the 0.3 blur alone across
    const double th = 3.14159265358979 * u(rng), c = std::cos(th), s = std::sin(th);
    const T a = T(c * c * s1 * s1 + s * s * s2 * s2 + 0.3);
    const T b = T(c * s * (s1 * s1 - s2 * s2));
    const T cc = T(s * s * s1 * s1 + c * c * s2 * s2 + 0.3);
    const T det = a * cc - b * b;
    if (!(det > T(0))) {
      p.radii[i] = 0;
      continue;
    }
    const T inv = T(1) / det;
    p.conic[i * 3] = cc * inv;
    p.conic[i * 3 + 1] = -b * inv;
    p.conic[i * 3 + 2] = a * inv;
    const T mid = T(0.5) * (a + cc);
    p.radii[i] = int(std::ceil(3 * std::sqrt(double(mid) + std::sqrt(std::max(0.1, double(mid * mid - det))))));
    p.mean2d[i * 2] = T(mx);
    p.mean2d[i * 2 + 1] = T(my);
    p.opacity[i] = T(kind == 4 ? 0.99 : 0.004 + 0.9 * u(rng));
    p.depth[i] = T(1 + 10 * u(rng));
    for (int k = 0; k < 3; ++k) p.color[i * 3 + k] = T(u(rng));
  }
  return p;
}

struct CullStats {
  std::size_t rect_tiles = 0, dropped = 0, chord_empty = 0;
  std::size_t untested = 0, untested_chord_empty = 0;  // Gaussians too elongated for the test; their empty tiles
};

// Every tile of every rectangle: dropped ones must be missed by every row's chord (alpha_row_span, the
// tile loops' test) and reach the cutoff at no pixel centre (alpha in double).
template <typename T>
CullStats check_dropped_tiles(const Projected<T>& p, int width, int height, double alpha_min, const std::string& label) {
  Binning<T> bin;
  render::cpu::bin_gaussians(p, width, height, alpha_min, bin);
  CullStats st;
  std::size_t bad_chord = 0, bad_pixel = 0;
  for (std::size_t i = 0; i < p.count; ++i) {
    const int* rect = &bin.rect[i * 4];
    if (rect[2] <= rect[0]) continue;
    std::vector<char> kept(static_cast<std::size_t>(bin.tiles_x * bin.tiles_y), 0);
    for (int j = 0; j < bin.tile_count[i]; ++j) kept[static_cast<std::size_t>(bin.rect_tiles[bin.rect_offsets[i] + j])] = 1;
    const T mx = p.mean2d[i * 2], my = p.mean2d[i * 2 + 1];
    const T qa = p.conic[i * 3], qb = p.conic[i * 3 + 1], qc = p.conic[i * 3 + 2], o = p.opacity[i];
    const T reach = T(2) * render::hd_log(o / T(alpha_min)), inv_qa = T(1) / qa;
    const int* box = &bin.box[i * 4];
    const bool untested = render::tile_reach_setup(mx, my, &p.conic[i * 3], reach, box, height).all;
    st.untested += untested;
    for (int ty = rect[1]; ty < rect[3]; ++ty)
      for (int tx = rect[0]; tx < rect[2]; ++tx) {
        ++st.rect_tiles;
        const int px0 = tx * kTileSize, py0 = ty * kTileSize;
        const int y_lo = std::max(py0, box[2]), y_hi = std::min({py0 + kTileSize - 1, height - 1, box[3]});
        bool chord_meets = false;
        for (int y = y_lo; y <= y_hi; ++y) {
          T x_lo, x_hi;
          if (render::alpha_row_span(mx, my - T(y), qa, qb, qc, reach, inv_qa, x_lo, x_hi) &&
              x_lo <= T(px0 + kTileSize - 1) && x_hi >= T(px0))
            chord_meets = true;
        }
        st.chord_empty += !chord_meets;
        st.untested_chord_empty += untested && !chord_meets;
        if (kept[static_cast<std::size_t>(ty * bin.tiles_x + tx)]) continue;
        ++st.dropped;
        bad_chord += chord_meets;
        for (int y = py0; y < std::min(py0 + kTileSize, height); ++y)
          for (int x = px0; x < std::min(px0 + kTileSize, width); ++x) {
            const double dx = double(mx) - x, dy = double(my) - y;
            const double q = double(qa) * dx * dx + 2 * double(qb) * dx * dy + double(qc) * dy * dy;
            const double alpha = std::min(render::kAlphaMax, double(o) * std::exp(-0.5 * q));
            bad_pixel += alpha >= alpha_min;
          }
      }
  }
  EXPECT_EQ(bad_chord, 0u) << label;
  EXPECT_EQ(bad_pixel, 0u) << label;
  // Not vacuous, and close to the chord test: nearly every tile no chord meets is dropped, except those of
  // the Gaussians too elongated for the test (axis ratio beyond ~2000: all kept).
  EXPECT_GT(st.dropped, st.rect_tiles / 10) << label;
  EXPECT_GE(double(st.dropped), 0.97 * double(st.chord_empty - st.untested_chord_empty)) << label;
  std::printf("%s: %zu rectangle tiles, %zu dropped, %zu met by no chord (%zu of them of the %zu Gaussians too "
              "elongated to test)\n",
              label.c_str(), st.rect_tiles, st.dropped, st.chord_empty, st.untested_chord_empty, st.untested);
  return st;
}

TEST(TileCull, DroppedTilesReachNoPixel) {
  for (unsigned seed : {1u, 2u, 3u}) {
    const int width = 161 + int(seed) * 16, height = 120 + int(seed) * 5;
    const auto pf = random_projected<float>(8000, width, height, seed);
    check_dropped_tiles(pf, width, height, render::kAlphaMin, "float hard cutoff, seed " + std::to_string(seed));
    check_dropped_tiles(pf, width, height, render::kSmoothAlphaLo, "float smooth cutoff, seed " + std::to_string(seed));
  }
  const auto pd = random_projected<double>(6000, 200, 150, 9);
  check_dropped_tiles(pd, 200, 150, render::kAlphaMin, "double hard cutoff");
}

// A Gaussian whose conic is too elongated for the determinant's bound (or degenerate) keeps its whole
// rectangle; a round one keeps, in each tile row, the tiles its chords meet.
TEST(TileCull, DegenerateConicsKeepTheirRectangleARoundOneItsChords) {
  const int box[4] = {-100, 100, -100, 100}, rect[4] = {0, 0, 8, 8};
  const float needle[3] = {1.0f, 0.9999999f, 1.0f};  // det ~ 1e-7 of qa qc: below the rounding bound
  EXPECT_TRUE(render::tile_reach_setup(10.0f, 10.0f, needle, 11.0f, box, 64).all);
  const float not_pd[3] = {-1.0f, 0.0f, 1.0f};
  EXPECT_TRUE(render::tile_reach_setup(10.0f, 10.0f, not_pd, 11.0f, box, 64).all);
  const float round[3] = {0.01f, 0.0f, 0.01f};  // radius sqrt(11 / 0.01) ~ 33 px about (40, 40)
  const auto t = render::tile_reach_setup(40.0f, 40.0f, round, 11.0f, box, 200);
  ASSERT_FALSE(t.all);
  int x0, x1;
  render::tile_reach_columns(t, 2, rect, x0, x1);  // rows 32-47: chord x 6.8 ... 73.2
  EXPECT_EQ(x0, 0);
  EXPECT_EQ(x1, 5);
  render::tile_reach_columns(t, 0, rect, x0, x1);  // rows 0-15: the chord of row 15 is x 18.2 ... 61.8
  EXPECT_EQ(x0, 1);
  EXPECT_EQ(x1, 4);
  render::tile_reach_columns(t, 5, rect, x0, x1);  // rows 80-95: beyond the circle
  EXPECT_EQ(x0, x1);
}

template <typename T>
bool same_bits(const std::vector<T>& a, const std::vector<T>& b, std::size_t n) {
  return a.size() >= n && b.size() >= n && std::memcmp(a.data(), b.data(), n * sizeof(T)) == 0;
}

// The CPU stages with and without the cull: images, final transmittance and every projected gradient
// bit for bit.
template <typename T>
void expect_cull_changes_nothing(const TestModel<T>& m, const render::CameraParams<T>& cam, bool smooth,
                                 bool pass_through, const std::string& label) {
  const auto view = m.view();
  Projected<T> proj;
  render::cpu::project_forward(view, m.multiplier.data(), cam, proj);
  render::cpu::sh_forward(view, 3, cam, proj);
  const std::size_t n = m.size(), pixels = std::size_t(cam.width) * cam.height;
  std::vector<T> w(pixels * 5);
  for (std::size_t i = 0; i < w.size(); ++i) w[i] = T(std::sin(double(i) * 0.37));
  const T bg[3] = {T(0.1), T(0.2), T(0.3)};
  struct Out {
    std::vector<T> rgb, alpha, depth, isect;
    render::cpu::PixelState<T> state;
    render::cpu::ProjectedGrads<T> g;
    std::size_t intersections = 0;
  } out[2];
  const double alpha_min = smooth ? render::kSmoothAlphaLo : render::kAlphaMin;
  for (int cull = 0; cull < 2; ++cull) {
    Out& o = out[cull];
    Binning<T> bin;
    render::cpu::bin_gaussians(proj, cam.width, cam.height, alpha_min, bin, cull == 1);
    o.rgb.resize(pixels * 3);
    o.alpha.resize(pixels);
    o.depth.resize(pixels);
    o.state.final_transmittance.resize(pixels);
    o.state.n_contrib.resize(pixels);
    render::cpu::composite_forward(bin, bg, smooth, o.rgb.data(), o.alpha.data(), o.depth.data(), o.state);
    render::cpu::composite_backward(bin, bg, smooth, pass_through, o.state, w.data(), w.data() + pixels * 3,
                                    w.data() + pixels * 4, n, o.isect, o.g);
    o.intersections = bin.intersections;
  }
  EXPECT_LT(out[1].intersections, out[0].intersections) << label;
  std::printf("%s: %zu intersections without the cull, %zu with it\n", label.c_str(), out[0].intersections,
              out[1].intersections);
  EXPECT_TRUE(same_bits(out[0].rgb, out[1].rgb, pixels * 3)) << label;
  EXPECT_TRUE(same_bits(out[0].alpha, out[1].alpha, pixels)) << label;
  EXPECT_TRUE(same_bits(out[0].depth, out[1].depth, pixels)) << label;
  EXPECT_TRUE(same_bits(out[0].state.final_transmittance, out[1].state.final_transmittance, pixels)) << label;
  EXPECT_TRUE(same_bits(out[0].g.mean2d, out[1].g.mean2d, n * 2)) << label;
  EXPECT_TRUE(same_bits(out[0].g.conic, out[1].g.conic, n * 3)) << label;
  EXPECT_TRUE(same_bits(out[0].g.opacity, out[1].g.opacity, n)) << label;
  EXPECT_TRUE(same_bits(out[0].g.color, out[1].g.color, n * 3)) << label;
  EXPECT_TRUE(same_bits(out[0].g.depth, out[1].g.depth, n)) << label;
  double sum = 0;
  for (std::size_t i = 0; i < n * 3; ++i) sum += std::abs(double(out[1].g.conic[i]));
  EXPECT_GT(sum, 0.0) << label;
}

// random_model with one axis of every Gaussian stretched (more tiles of the rectangles missed).
template <typename T>
TestModel<T> elongated_model(const render::CameraParams<T>& cam, int n, unsigned seed, double max_opacity) {
  TestModel<T> m = random_model(cam, n, seed, max_opacity);
  for (std::size_t i = 0; i < m.size(); ++i) {
    m.log_scales[i * 3 + i % 3] += T(1.5);
    m.log_scales[i * 3 + (i + 1) % 3] -= T(1.0);
  }
  return m;
}

TEST(TileCull, RendersAndGradientsBitIdenticalWithAndWithoutTheCull) {
  const auto cam = test_camera<float>(200, 150, 3);
  const auto m = elongated_model(cam, 3000, 4, 0.99);
  expect_cull_changes_nothing(m, cam, false, false, "float, opaque");
  expect_cull_changes_nothing(m, cam, false, true, "float, opaque, clamp pass-through");
  expect_cull_changes_nothing(m, cam, true, false, "float, smooth cutoff");
  const auto m2 = elongated_model(cam, 3000, 5, 0.6);
  expect_cull_changes_nothing(m2, cam, false, false, "float");
  const auto camd = test_camera<double>(120, 90, 6);
  const auto md = elongated_model(camd, 800, 7, 0.9);
  expect_cull_changes_nothing(md, camd, false, false, "double");
  expect_cull_changes_nothing(md, camd, true, false, "double, smooth cutoff");
}

}  // namespace
}  // namespace d2gs::test
