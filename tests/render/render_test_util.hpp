#pragma once
// Small random scenes for the rasterizer tests, in any scalar type.
#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "d2gs/render/cpu/cpu_rasterizer.hpp"

namespace d2gs::test {

template <typename T>
struct TestModel {
  int sh_degree = 3;
  std::vector<T> means, log_scales, quats, opacity_logits, sh_dc, sh_rest, multiplier;
  std::size_t size() const { return opacity_logits.size(); }
  int K() const { return (sh_degree + 1) * (sh_degree + 1) - 1; }
  render::cpu::ModelView<T> view() const {
    render::cpu::ModelView<T> v;
    v.count = size();
    v.sh_degree = sh_degree;
    v.means = means.data();
    v.log_scales = log_scales.data();
    v.quats = quats.data();
    v.opacity_logits = opacity_logits.data();
    v.sh_dc = sh_dc.data();
    v.sh_rest = sh_rest.data();
    return v;
  }
  // All parameter arrays, in a fixed order (for finite differences over every parameter).
  std::vector<std::vector<T>*> arrays() {
    return {&means, &log_scales, &quats, &opacity_logits, &sh_dc, &sh_rest};
  }
  template <typename U>
  TestModel<U> cast() const {
    TestModel<U> m;
    m.sh_degree = sh_degree;
    auto c = [](const std::vector<T>& a) { return std::vector<U>(a.begin(), a.end()); };
    m.means = c(means); m.log_scales = c(log_scales); m.quats = c(quats);
    m.opacity_logits = c(opacity_logits); m.sh_dc = c(sh_dc); m.sh_rest = c(sh_rest);
    m.multiplier = c(multiplier);
    return m;
  }
};

template <typename T>
struct TestGrads {
  std::vector<T> means, log_scales, quats, opacity_logits, sh_dc, sh_rest, mean2d_ndc;
  void resize(const TestModel<T>& m) {
    const std::size_t n = m.size();
    means.assign(n * 3, 0); log_scales.assign(n * 3, 0); quats.assign(n * 4, 0);
    opacity_logits.assign(n, 0); sh_dc.assign(n * 3, 0); sh_rest.assign(n * m.K() * 3, 0);
    mean2d_ndc.assign(n * 2, 0);
  }
  render::cpu::ModelGradView<T> view() {
    return {means.data(), log_scales.data(), quats.data(), opacity_logits.data(), sh_dc.data(), sh_rest.data()};
  }
  std::vector<std::vector<T>*> arrays() {
    return {&means, &log_scales, &quats, &opacity_logits, &sh_dc, &sh_rest};
  }
};

// A camera near the origin, slightly rotated, looking along +z, with an off-centre principal point.
template <typename T>
render::CameraParams<T> test_camera(int width, int height, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  render::CameraParams<T> cam;
  cam.width = width;
  cam.height = height;
  cam.fx = T(0.9 * width);
  cam.fy = T(0.95 * width);
  cam.cx = T(0.5 * width + 0.13 * width);
  cam.cy = T(0.5 * height - 0.07 * height);
  // Small rotation about a random axis (Rodrigues).
  double ax = u(rng), ay = u(rng), az = u(rng);
  const double norm = std::sqrt(ax * ax + ay * ay + az * az);
  ax /= norm; ay /= norm; az /= norm;
  const double th = 0.15, c = std::cos(th), s = std::sin(th), C = 1 - c;
  const double R[9] = {c + ax * ax * C,      ax * ay * C - az * s, ax * az * C + ay * s,
                       ay * ax * C + az * s, c + ay * ay * C,      ay * az * C - ax * s,
                       az * ax * C - ay * s, az * ay * C + ax * s, c + az * az * C};
  const double centre[3] = {0.1 * u(rng), 0.1 * u(rng), -0.2};
  for (int i = 0; i < 9; ++i) cam.R[i] = T(R[i]);
  for (int i = 0; i < 3; ++i) {
    cam.campos[i] = T(centre[i]);
    cam.t[i] = T(-(R[i * 3] * centre[0] + R[i * 3 + 1] * centre[1] + R[i * 3 + 2] * centre[2]));
  }
  render::set_jacobian_limits(cam);
  return cam;
}

// n Gaussians in front of `cam` (a few behind the near plane when `behind`), SH degree 3.
template <typename T>
TestModel<T> random_model(const render::CameraParams<T>& cam, int n, unsigned seed, double max_opacity = 0.6,
                          bool behind = true) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::normal_distribution<double> g(0.0, 1.0);
  TestModel<T> m;
  m.sh_degree = 3;
  const int K = m.K();
  for (int i = 0; i < n; ++i) {
    const double z = (behind && i % 10 == 9) ? 0.05 + 0.1 * u(rng) : 1.5 + 3.0 * u(rng);
    // Camera-space position spread a bit beyond the image (exercises the Jacobian clamp), then world.
    const double xc = (u(rng) * 1.5 - 0.75) * z * cam.width / double(cam.fx);
    const double yc = (u(rng) * 1.5 - 0.75) * z * cam.height / double(cam.fy);
    const double pc[3] = {xc, yc, z};
    for (int k = 0; k < 3; ++k) {
      // x = R^T (pc - t)
      double w = 0;
      for (int r = 0; r < 3; ++r) w += double(cam.R[r * 3 + k]) * (pc[r] - double(cam.t[r]));
      m.means.push_back(T(w));
    }
    const double base = std::log(z * (3.0 + 5.0 * u(rng)) / double(cam.fx));
    for (int k = 0; k < 3; ++k) m.log_scales.push_back(T(base + 0.5 * g(rng)));
    for (int k = 0; k < 4; ++k) m.quats.push_back(T(g(rng) + (k == 0 ? 1.0 : 0.0)));
    const double op = 0.1 + (max_opacity - 0.1) * u(rng);
    m.opacity_logits.push_back(T(std::log(op / (1 - op))));
    for (int c = 0; c < 3; ++c) m.sh_dc.push_back(T(0.3 + 0.6 * g(rng)));
    for (int k = 0; k < K * 3; ++k) m.sh_rest.push_back(T(0.15 * g(rng)));
    m.multiplier.push_back(T(i % 7 == 3 ? 0.5 : 1.0));
  }
  return m;
}

// Relative L2 difference of a float array from its double reference.
inline double rel_l2(const std::vector<float>& a, const std::vector<double>& ref) {
  double num = 0, den = 0;
  for (std::size_t i = 0; i < ref.size(); ++i) {
    const double d = double(a[i]) - ref[i];
    num += d * d;
    den += ref[i] * ref[i];
  }
  return std::sqrt(num / std::max(den, 1e-300));
}

// A float image against the double renderer's: mean absolute difference below 1e-5, and at most 1 value in
// 200 off by more than 1e-4 (pixels where float and double decide a cutoff differently).
inline void expect_image_close_to_double(const std::vector<float>& f, const std::vector<double>& d) {
  double mean = 0;
  std::size_t far = 0;
  for (std::size_t i = 0; i < d.size(); ++i) {
    const double e = std::abs(double(f[i]) - d[i]);
    mean += e;
    far += e > 1e-4;
  }
  mean /= double(d.size());
  EXPECT_LT(mean, 1e-5);
  EXPECT_LE(far, d.size() / 200);
}

}  // namespace d2gs::test
