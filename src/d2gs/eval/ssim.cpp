#include "d2gs/eval/ssim.hpp"

#include <array>
#include <cmath>
#include <cstddef>

#include "d2gs/core/error.hpp"
#include "d2gs/core/vector_clones.hpp"

namespace d2gs {
namespace {

template <typename T>
std::array<T, kSsimWindow> gaussian_window() {
  std::array<double, kSsimWindow> g{};
  double sum = 0;
  for (int i = 0; i < kSsimWindow; ++i) {
    const double x = i - kSsimWindow / 2;
    g[i] = std::exp(-(x * x) / (2.0 * kSsimSigma * kSsimSigma));
    sum += g[i];
  }
  std::array<T, kSsimWindow> out{};
  for (int i = 0; i < kSsimWindow; ++i) out[i] = static_cast<T>(g[i] / sum);
  return out;
}

// dst[x] += w * src[x] for x < n: the inner loop of both blur passes, multi-versioned for float.
D2GS_VECTOR_CLONES void axpy(float* __restrict dst, const float* __restrict src, float w, int n) {
  for (int x = 0; x < n; ++x) dst[x] += w * src[x];
}
void axpy(double* __restrict dst, const double* __restrict src, double w, int n) {
  for (int x = 0; x < n; ++x) dst[x] += w * src[x];
}

}  // namespace

template <typename T>
void Ssim<T>::resize(int width, int height) {
  if (width == width_ && height == height_) return;
  width_ = width;
  height_ = height;
  const std::size_t n = static_cast<std::size_t>(width) * height;
  for (auto* v : {&a_, &b_, &mu_a_, &mu_b_, &s_aa_, &s_bb_, &s_ab_, &tmp_, &d_mu_, &d_saa_, &d_sab_, &acc_})
    v->assign(n, T(0));
  row_.assign(static_cast<std::size_t>(width) + kSsimWindow, T(0));
}

// Zero-padded "same" separable filtering of one plane: horizontal pass into tmp_, vertical into out.
template <typename T>
void Ssim<T>::blur(const T* in, T* out) {
  static const auto w = gaussian_window<T>();
  constexpr int r = kSsimWindow / 2;
  const int W = width_, H = height_;
  T* tmp = tmp_.data();
#pragma omp parallel for schedule(static)
  for (int y = 0; y < H; ++y) {
    const T* src = in + static_cast<std::size_t>(y) * W;
    T* dst = tmp + static_cast<std::size_t>(y) * W;
    for (int x = 0; x < W; ++x) dst[x] = T(0);
    for (int k = 0; k < kSsimWindow; ++k) {
      const int shift = k - r;  // dst[x] += w[k] * src[x + shift]
      const int x0 = shift < 0 ? -shift : 0;
      const int x1 = shift > 0 ? W - shift : W;
      axpy(dst + x0, src + x0 + shift, w[k], x1 - x0);
    }
  }
#pragma omp parallel for schedule(static)
  for (int y = 0; y < H; ++y) {
    T* dst = out + static_cast<std::size_t>(y) * W;
    for (int x = 0; x < W; ++x) dst[x] = T(0);
    for (int k = 0; k < kSsimWindow; ++k) {
      const int yy = y + k - r;
      if (yy < 0 || yy >= H) continue;
      axpy(dst, tmp + static_cast<std::size_t>(yy) * W, w[k], W);
    }
  }
}

template <typename T>
T Ssim<T>::evaluate(const T* a, const T* b, int width, int height, int channels, T* grad_a, T grad_scale) {
  if (width <= 0 || height <= 0 || channels <= 0) fail("SSIM: invalid image size {}x{}x{}", width, height, channels);
  resize(width, height);
  const std::size_t n = static_cast<std::size_t>(width) * height;
  const T C1 = static_cast<T>(kSsimC1), C2 = static_cast<T>(kSsimC2);
  const double inv_count = 1.0 / (static_cast<double>(n) * channels);
  double total = 0.0;
  for (int c = 0; c < channels; ++c) {
    // De-interleave the channel and form the products.
    for (std::size_t i = 0; i < n; ++i) {
      a_[i] = a[i * channels + c];
      b_[i] = b[i * channels + c];
    }
    for (std::size_t i = 0; i < n; ++i) acc_[i] = a_[i] * a_[i];
    blur(acc_.data(), s_aa_.data());
    for (std::size_t i = 0; i < n; ++i) acc_[i] = b_[i] * b_[i];
    blur(acc_.data(), s_bb_.data());
    for (std::size_t i = 0; i < n; ++i) acc_[i] = a_[i] * b_[i];
    blur(acc_.data(), s_ab_.data());
    blur(a_.data(), mu_a_.data());
    blur(b_.data(), mu_b_.data());

    // SSIM map, its row sums (fixed order: deterministic), and the local derivatives.
    std::vector<double> row_sums(static_cast<std::size_t>(height), 0.0);
    const T g = static_cast<T>(grad_scale * static_cast<T>(inv_count));
#pragma omp parallel for schedule(static)
    for (int y = 0; y < height; ++y) {
      double row_sum = 0.0;
      for (int x = 0; x < width; ++x) {
        const std::size_t i = static_cast<std::size_t>(y) * width + x;
        const T ma = mu_a_[i], mb = mu_b_[i];
        const T var_a = s_aa_[i] - ma * ma, var_b = s_bb_[i] - mb * mb, cov = s_ab_[i] - ma * mb;
        const T A1 = T(2) * ma * mb + C1, A2 = T(2) * cov + C2;
        const T B1 = ma * ma + mb * mb + C1, B2 = var_a + var_b + C2;
        const T inv_b = T(1) / (B1 * B2);
        const T s = A1 * A2 * inv_b;
        row_sum += static_cast<double>(s);
        if (grad_a) {
          // dS/dmu_a, dS/d<a²>, dS/d<ab> (local means), scaled for the mean and the caller's factor.
          d_mu_[i] = g * ((T(2) * mb * A2 - T(2) * mb * A1) * inv_b - s * (T(2) * ma / B1 - T(2) * ma / B2));
          d_saa_[i] = g * (-s / B2);
          d_sab_[i] = g * (T(2) * A1 * inv_b);
        }
      }
      row_sums[static_cast<std::size_t>(y)] = row_sum;
    }
    for (double r : row_sums) total += r;

    if (grad_a) {
      // grad_a = G*(dS/dmu_a) + 2a·G*(dS/d<a²>) + b·G*(dS/d<ab>)   (G self-adjoint)
      blur(d_mu_.data(), mu_a_.data());
      blur(d_saa_.data(), s_aa_.data());
      blur(d_sab_.data(), s_ab_.data());
      for (std::size_t i = 0; i < n; ++i)
        grad_a[i * channels + c] = mu_a_[i] + T(2) * a_[i] * s_aa_[i] + b_[i] * s_ab_[i];
    }
  }
  return static_cast<T>(total * inv_count);
}

template class Ssim<float>;
template class Ssim<double>;

double ssim(const float* a, const float* b, int width, int height, int channels) {
  const std::size_t n = static_cast<std::size_t>(width) * height * channels;
  std::vector<double> da(a, a + n), db(b, b + n);
  Ssim<double> s;
  return s.evaluate(da.data(), db.data(), width, height, channels);
}

}  // namespace d2gs
