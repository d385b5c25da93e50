#pragma once
// The benchmarks' synthetic LLFF-like model at LLFF 1/8 resolution (504 x 378), shared by bench_render
// (the CPU rasterizer) and bench_cuda (the CUDA stages).
//
// Generator (seeded, deterministic): a forward-facing camera (fx = fy = 407.6, principal point at the
// image centre, identity pose). Depths z = 1.5 * (100/1.5)^(u^2), u ~ U(0,1): spread 1.5..100 with more
// near (median ~4). x/z, y/z uniform over 1.1x the field of view. Sizes as a kNN initialisation of a
// trained model would give: a screen-space standard deviation s ~ lognormal(median 1.5 px, sigma 0.6)
// clipped to [0.3, 40] px, world scale = s z / fx, per-axis factor exp(N(0, 0.3)); random rotations.
// Opacity = sigmoid(N(0.5, 1.5)); SH degree 3, DC ~ N(0, 0.5), rest ~ N(0, 0.1).
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <random>

#include "d2gs/model/gaussians.hpp"
#include "d2gs/scene/camera.hpp"

namespace d2gs::bench {

constexpr int kWidth = 504, kHeight = 378;
constexpr double kFocal = 407.6;

inline Camera llff_camera() {
  Camera c;
  c.width = kWidth;
  c.height = kHeight;
  c.fx = c.fy = kFocal;
  c.cx = 0.5 * kWidth;
  c.cy = 0.5 * kHeight;
  return c;
}

inline Gaussians llff_like_model(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::normal_distribution<double> g(0.0, 1.0);
  Gaussians m;
  m.resize(n, 3);
  const int K = m.sh_rest_count();
  for (std::size_t i = 0; i < n; ++i) {
    const double a = u(rng);
    const double z = 1.5 * std::pow(100.0 / 1.5, a * a);
    const double x = (u(rng) - 0.5) * 1.1 * kWidth / kFocal * z;
    const double y = (u(rng) - 0.5) * 1.1 * kHeight / kFocal * z;
    m.means[i * 3] = float(x);
    m.means[i * 3 + 1] = float(y);
    m.means[i * 3 + 2] = float(z);
    const double s_px = std::clamp(1.5 * std::exp(0.6 * g(rng)), 0.3, 40.0);
    const double base = std::log(s_px * z / kFocal);
    for (int k = 0; k < 3; ++k) m.log_scales[i * 3 + k] = float(base + 0.3 * g(rng));
    for (int k = 0; k < 4; ++k) m.quats[i * 4 + k] = float(g(rng));
    m.opacity_logits[i] = float(0.5 + 1.5 * g(rng));
    for (int c = 0; c < 3; ++c) m.sh_dc[i * 3 + c] = float(0.5 * g(rng));
    for (int k = 0; k < K * 3; ++k) m.sh_rest[i * K * 3 + k] = float(0.1 * g(rng));
  }
  return m;
}

}  // namespace d2gs::bench
