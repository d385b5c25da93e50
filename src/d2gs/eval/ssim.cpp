#include "d2gs/eval/ssim.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>

#include "d2gs/core/error.hpp"
#include "d2gs/core/vector_clones.hpp"

namespace d2gs {
namespace {

// Blur of one row: dst[x] = Σ_k w[k]·src[x + k − r] over the taps inside the row, summed in k order
// starting from 0 — the operations of the former 11 axpy passes per row, so results are bit-identical
// (with the same contraction into fused multiply-adds). The interior is one pass with the 11 taps in
// registers instead of 11 read-modify-write passes over the row.
template <typename T>
D2GS_ALWAYS_INLINE void blur_row_body(T* __restrict dst, const T* __restrict src, const T* __restrict w, int W) {
  constexpr int r = kSsimWindow / 2;
  const int lo = std::min(r, W), hi = std::max(lo, W - r);
  const auto edge = [&](int x) {
    T acc = T(0);
    for (int k = 0; k < kSsimWindow; ++k) {
      const int xx = x + k - r;
      if (xx >= 0 && xx < W) acc += w[k] * src[xx];
    }
    dst[x] = acc;
  };
  for (int x = 0; x < lo; ++x) edge(x);
  for (int x = lo; x < hi; ++x) {
    const T* s = src + x - r;
    T acc = T(0);
#pragma GCC unroll 16
    for (int k = 0; k < kSsimWindow; ++k) acc += w[k] * s[k];
    dst[x] = acc;
  }
  for (int x = hi; x < W; ++x) edge(x);
}

// Vertical pass of one output row with all 11 input rows inside the image: dst[x] = Σ_k w[k]·rows[k][x]
// in k order from 0 (the former per-row axpy passes, bit-identical).
template <typename T>
D2GS_ALWAYS_INLINE void blur_column_body(T* __restrict dst, const T* __restrict in, std::size_t stride,
                                          const T* __restrict w, int W) {
  for (int x = 0; x < W; ++x) {
    const T* s = in + x;
    T acc = T(0);
#pragma GCC unroll 16
    for (int k = 0; k < kSsimWindow; ++k) acc += w[k] * s[static_cast<std::size_t>(k) * stride];
    dst[x] = acc;
  }
}

D2GS_VECTOR_CLONES void blur_row(float* __restrict dst, const float* __restrict src, const float* __restrict w, int W) {
  blur_row_body(dst, src, w, W);
}
void blur_row(double* __restrict dst, const double* __restrict src, const double* __restrict w, int W) {
  blur_row_body(dst, src, w, W);
}
D2GS_VECTOR_CLONES void blur_column(float* __restrict dst, const float* __restrict in, std::size_t stride,
                                    const float* __restrict w, int W) {
  blur_column_body(dst, in, stride, w, W);
}
void blur_column(double* __restrict dst, const double* __restrict in, std::size_t stride, const double* __restrict w,
                 int W) {
  blur_column_body(dst, in, stride, w, W);
}

// dst[x] += w * src[x] for x < n: the vertical pass at the top and bottom rows.
D2GS_VECTOR_CLONES void axpy(float* __restrict dst, const float* __restrict src, float w, int n) {
  for (int x = 0; x < n; ++x) dst[x] += w * src[x];
}
void axpy(double* __restrict dst, const double* __restrict src, double w, int n) {
  for (int x = 0; x < n; ++x) dst[x] += w * src[x];
}

// One row of the SSIM map, and with Grad its local derivatives dS/dmu_a, dS/d<a²>, dS/d<ab> scaled by g
// (for the mean and the caller's factor).
template <typename T, bool Grad>
void ssim_map_row(const T* __restrict mu_a, const T* __restrict mu_b, const T* __restrict s_aa,
                  const T* __restrict s_bb, const T* __restrict s_ab, int width, T C1, T C2, T g, T* __restrict map,
                  T* __restrict d_mu, T* __restrict d_saa, T* __restrict d_sab) {
  for (int x = 0; x < width; ++x) {
    if constexpr (Grad) {
      // Into locals, then stored: with the array elements' addresses passed in, GCC left this loop scalar.
      T dm, dsa, dsb;
      map[x] = ssim_pixel<T, true>(mu_a[x], mu_b[x], s_aa[x], s_bb[x], s_ab[x], C1, C2, g, &dm, &dsa, &dsb);
      d_mu[x] = dm;
      d_saa[x] = dsa;
      d_sab[x] = dsb;
    } else
      map[x] = ssim_pixel<T, false>(mu_a[x], mu_b[x], s_aa[x], s_bb[x], s_ab[x], C1, C2, g, nullptr, nullptr, nullptr);
  }
}

}  // namespace

template <typename T>
std::array<T, kSsimWindow> ssim_window() {
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

template std::array<float, kSsimWindow> ssim_window<float>();
template std::array<double, kSsimWindow> ssim_window<double>();

template <typename T>
void Ssim<T>::resize(int width, int height) {
  if (width == width_ && height == height_) return;
  width_ = width;
  height_ = height;
  const std::size_t n = static_cast<std::size_t>(width) * height;
  for (auto* v : {&a_, &mu_a_, &s_aa_, &s_ab_, &tmp_, &d_mu_, &d_saa_, &d_sab_, &acc_, &map_}) v->assign(n, T(0));
  row_sums_.assign(static_cast<std::size_t>(height), 0.0);
}

// Zero-padded "same" separable filtering of one plane: horizontal pass into tmp_, vertical into out.
template <typename T>
void Ssim<T>::blur(const T* in, T* out) {
  static const auto w = ssim_window<T>();
  constexpr int r = kSsimWindow / 2;
  const int W = width_, H = height_;
  T* tmp = tmp_.data();
#pragma omp parallel for schedule(static)
  for (int y = 0; y < H; ++y)
    blur_row(tmp + static_cast<std::size_t>(y) * W, in + static_cast<std::size_t>(y) * W, w.data(), W);
#pragma omp parallel for schedule(static)
  for (int y = 0; y < H; ++y) {
    T* dst = out + static_cast<std::size_t>(y) * W;
    if (y >= r && y + r < H) {
      blur_column(dst, tmp + static_cast<std::size_t>(y - r) * W, static_cast<std::size_t>(W), w.data(), W);
      continue;
    }
    for (int x = 0; x < W; ++x) dst[x] = T(0);
    for (int k = 0; k < kSsimWindow; ++k) {
      const int yy = y + k - r;
      if (yy < 0 || yy >= H) continue;
      axpy(dst, tmp + static_cast<std::size_t>(yy) * W, w[k], W);
    }
  }
}

template <typename T>
typename Ssim<T>::Reference Ssim<T>::reference(const T* b, int width, int height, int channels) {
  if (width <= 0 || height <= 0 || channels <= 0) fail("SSIM: invalid image size {}x{}x{}", width, height, channels);
  resize(width, height);
  const std::size_t n = static_cast<std::size_t>(width) * height;
  Reference ref;
  ref.width = width;
  ref.height = height;
  ref.channels = channels;
  for (auto* v : {&ref.b, &ref.mu_b, &ref.s_bb}) v->assign(n * static_cast<std::size_t>(channels), T(0));
  for (int c = 0; c < channels; ++c) {
    T* plane = ref.b.data() + n * static_cast<std::size_t>(c);
    for (std::size_t i = 0; i < n; ++i) plane[i] = b[i * channels + c];
    for (std::size_t i = 0; i < n; ++i) acc_[i] = plane[i] * plane[i];
    blur(acc_.data(), ref.s_bb.data() + n * static_cast<std::size_t>(c));
    blur(plane, ref.mu_b.data() + n * static_cast<std::size_t>(c));
  }
  return ref;
}

template <typename T>
T Ssim<T>::evaluate(const T* a, const T* b, int width, int height, int channels, T* grad_a, T grad_scale) {
  return evaluate(a, reference(b, width, height, channels), grad_a, grad_scale);
}

template <typename T>
T Ssim<T>::evaluate(const T* a, const Reference& ref, T* grad_a, T grad_scale) {
  if (ref.width <= 0 || ref.height <= 0 || ref.channels <= 0 ||
      ref.b.size() != static_cast<std::size_t>(ref.width) * ref.height * ref.channels)
    fail("SSIM: invalid reference image");
  const int width = ref.width, height = ref.height, channels = ref.channels;
  resize(width, height);
  const std::size_t n = static_cast<std::size_t>(width) * height;
  const T C1 = static_cast<T>(kSsimC1), C2 = static_cast<T>(kSsimC2);
  const double inv_count = 1.0 / (static_cast<double>(n) * channels);
  double total = 0.0;
  for (int c = 0; c < channels; ++c) {
    // The second image's plane, local mean and local second moment; de-interleave the first and form the
    // products.
    const std::size_t at = n * static_cast<std::size_t>(c);
    const T* bp = ref.b.data() + at;
    const T* mu_b = ref.mu_b.data() + at;
    const T* s_bb = ref.s_bb.data() + at;
    // (Per-pixel passes in parallel: each value is computed alone, so the split changes no bit.)
    const auto pixels = static_cast<std::ptrdiff_t>(n);
    T* pa = a_.data();
    T* acc = acc_.data();
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t i = 0; i < pixels; ++i) {
      pa[i] = a[i * channels + c];
      acc[i] = pa[i] * pa[i];
    }
    blur(acc, s_aa_.data());
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t i = 0; i < pixels; ++i) acc[i] = pa[i] * bp[i];
    blur(acc, s_ab_.data());
    blur(a_.data(), mu_a_.data());

    // SSIM map and the local derivatives (one vectorisable pass per row: the double row sum in pixel
    // order is a second pass, so that it does not keep the map's arithmetic scalar), and the map's row
    // sums (fixed order: deterministic).
    double* row_sums = row_sums_.data();
    const T g = static_cast<T>(grad_scale * static_cast<T>(inv_count));
    T* map = map_.data();
#pragma omp parallel for schedule(static)
    for (int y = 0; y < height; ++y) {
      const std::size_t row = static_cast<std::size_t>(y) * width;
      if (grad_a)
        ssim_map_row<T, true>(mu_a_.data() + row, mu_b + row, s_aa_.data() + row, s_bb + row, s_ab_.data() + row,
                              width, C1, C2, g, map + row, d_mu_.data() + row, d_saa_.data() + row,
                              d_sab_.data() + row);
      else
        ssim_map_row<T, false>(mu_a_.data() + row, mu_b + row, s_aa_.data() + row, s_bb + row, s_ab_.data() + row,
                               width, C1, C2, g, map + row, nullptr, nullptr, nullptr);
      double row_sum = 0.0;
      for (int x = 0; x < width; ++x) row_sum += static_cast<double>(map[row + static_cast<std::size_t>(x)]);
      row_sums[y] = row_sum;
    }
    for (int y = 0; y < height; ++y) total += row_sums[y];

    if (grad_a) {
      // grad_a += G*(dS/dmu_a) + 2a·G*(dS/d<a²>) + b·G*(dS/d<ab>)   (G self-adjoint)
      blur(d_mu_.data(), mu_a_.data());
      blur(d_saa_.data(), s_aa_.data());
      blur(d_sab_.data(), s_ab_.data());
      const T* g_mu = mu_a_.data();
      const T* g_saa = s_aa_.data();
      const T* g_sab = s_ab_.data();
#pragma omp parallel for schedule(static)
      for (std::ptrdiff_t i = 0; i < pixels; ++i)
        grad_a[i * channels + c] += ssim_input_gradient(g_mu[i], pa[i], g_saa[i], bp[i], g_sab[i]);
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
