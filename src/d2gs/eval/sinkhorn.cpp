#include "d2gs/eval/sinkhorn.hpp"

#include <omp.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <deque>
#include <limits>
#include <type_traits>

#include "d2gs/core/error.hpp"
#include "d2gs/core/interrupt.hpp"
#include "d2gs/core/vector_clones.hpp"

namespace d2gs {
namespace {

D2GS_ALWAYS_INLINE float exp_core(float x) {
  x = x < -86.0f ? -86.0f : x;
  x = x > 88.0f ? 88.0f : x;
  // x = k ln2 + r, |r| <= ln2/2; k by the 1.5·2^23 rounding trick (round to nearest).
  const float shifted = x * 1.44269504088896341f + 12582912.0f;
  const float kf = shifted - 12582912.0f;
  const std::int32_t k = std::bit_cast<std::int32_t>(shifted) - 0x4B400000;
  float r = x - kf * 0.693359375f;  // ln2 split in two parts: the first is exact in a few bits
  r = r - kf * -2.12194440054690583e-4f;
  // Taylor series of exp to degree 7 (truncation error < 6e-9 on |r| <= 0.347).
  float p = 1.0f / 5040.0f;
  p = p * r + 1.0f / 720.0f;
  p = p * r + 1.0f / 120.0f;
  p = p * r + 1.0f / 24.0f;
  p = p * r + 1.0f / 6.0f;
  p = p * r + 0.5f;
  p = p * r + 1.0f;
  p = p * r + 1.0f;
  return std::bit_cast<float>(std::bit_cast<std::int32_t>(p) + static_cast<std::int32_t>(
                                  static_cast<std::uint32_t>(k) << 23));
}

// The vector helpers below are always inlined, never called across an ABI boundary.
#pragma GCC diagnostic ignored "-Wpsabi"

// Explicit 8-lane vectors (GCC/Clang vector extensions): each target clone compiles them to its native
// width (2 x SSE, 1 x AVX-512, ...), and the summation order (8 lane partial sums, then lanes 0..7, then
// the tail) is fixed by the source, so all clones and all thread counts give the same bits.
typedef double v8d __attribute__((vector_size(64)));
typedef float v8f __attribute__((vector_size(32)));
typedef std::int32_t v8i __attribute__((vector_size(32)));
constexpr std::size_t kLanes = 8;

template <class T>
D2GS_ALWAYS_INLINE v8d load8(const T* p) {
  if constexpr (std::is_same_v<T, double>) {
    v8d v;
    std::memcpy(&v, p, sizeof v);
    return v;
  } else {
    v8f v;
    std::memcpy(&v, p, sizeof v);
    return __builtin_convertvector(v, v8d);
  }
}

D2GS_ALWAYS_INLINE v8f exp8(v8f x) {
  x = x < -86.0f ? v8f{} - 86.0f : x;
  x = x > 88.0f ? v8f{} + 88.0f : x;
  const v8f shifted = x * 1.44269504088896341f + 12582912.0f;
  const v8f kf = shifted - 12582912.0f;
  v8i k;
  std::memcpy(&k, &shifted, sizeof k);
  k -= 0x4B400000;
  v8f r = x - kf * 0.693359375f;
  r = r - kf * -2.12194440054690583e-4f;
  v8f p = v8f{} + 1.0f / 5040.0f;
  p = p * r + 1.0f / 720.0f;
  p = p * r + 1.0f / 120.0f;
  p = p * r + 1.0f / 24.0f;
  p = p * r + 1.0f / 6.0f;
  p = p * r + 0.5f;
  p = p * r + 1.0f;
  p = p * r + 1.0f;
  v8i bits;
  std::memcpy(&bits, &p, sizeof bits);
  bits += k << 23;
  v8f out;
  std::memcpy(&out, &bits, sizeof out);
  return out;
}

D2GS_ALWAYS_INLINE double hsum(v8d v) {
  double s = 0.0;
  for (std::size_t k = 0; k < kLanes; ++k) s += v[k];
  return s;
}

// max_j (pot_j − c_j·inv_eps)
template <class T>
D2GS_ALWAYS_INLINE double max_arg(const T* c, const double* pot, double inv_eps, std::size_t count) {
  constexpr double kNegInf = -std::numeric_limits<double>::infinity();
  v8d lanes = v8d{} + kNegInf;
  std::size_t j = 0;
  for (; j + kLanes <= count; j += kLanes) {
    const v8d v = load8(pot + j) - load8(c + j) * inv_eps;
    lanes = v > lanes ? v : lanes;
  }
  double m = kNegInf;
  for (std::size_t k = 0; k < kLanes; ++k) m = std::max(m, lanes[k]);
  for (; j < count; ++j) m = std::max(m, pot[j] - static_cast<double>(c[j]) * inv_eps);
  return m;
}

// log Σ_j exp(pot_j − c_j·inv_eps): the argument is formed and reduced by the maximum in double, then
// exponentiated in float (it lies in [-86, 0] where float keeps ~1e-7 relative accuracy) and summed in
// double.
template <class T>
D2GS_ALWAYS_INLINE double lse_body(const T* c, const double* pot, double inv_eps, std::size_t count) {
  const double m = max_arg(c, pot, inv_eps, count);
  if (!std::isfinite(m)) return m;
  v8d acc{};
  std::size_t j = 0;
  for (; j + kLanes <= count; j += kLanes) {
    const v8d v = load8(pot + j) - load8(c + j) * inv_eps - m;
    acc += __builtin_convertvector(exp8(__builtin_convertvector(v, v8f)), v8d);
  }
  double sum = hsum(acc);
  for (; j < count; ++j)
    sum += static_cast<double>(exp_core(static_cast<float>(pot[j] - static_cast<double>(c[j]) * inv_eps - m)));
  return m + std::log(sum);
}

// One pass instead of two: the same log-sum-exp with a guessed shift instead of the maximum (the
// previous iteration's value, which is close to the new one once the iteration settles). Returns NaN
// when the guess was poor (largest argument outside [-20, 20]) so the caller falls back to lse_body.
template <class T>
D2GS_ALWAYS_INLINE double lse_guess_body(const T* c, const double* pot, double inv_eps, std::size_t count,
                                         double guess) {
  v8d acc{}, top = v8d{} - std::numeric_limits<double>::infinity();
  std::size_t j = 0;
  for (; j + kLanes <= count; j += kLanes) {
    const v8d v = load8(pot + j) - load8(c + j) * inv_eps - guess;
    top = v > top ? v : top;
    acc += __builtin_convertvector(exp8(__builtin_convertvector(v, v8f)), v8d);
  }
  double sum = hsum(acc), mx = -std::numeric_limits<double>::infinity();
  for (std::size_t k = 0; k < kLanes; ++k) mx = std::max(mx, top[k]);
  for (; j < count; ++j) {
    const double v = pot[j] - static_cast<double>(c[j]) * inv_eps - guess;
    mx = std::max(mx, v);
    sum += static_cast<double>(exp_core(static_cast<float>(v)));
  }
  if (!(mx >= -20.0 && mx <= 20.0)) return std::numeric_limits<double>::quiet_NaN();
  return guess + std::log(sum);
}

// The same with std::exp in double (SinkhornOptions::double_exp).
template <class T>
double lse_precise(const T* c, const double* pot, double inv_eps, std::size_t count) {
  const double m = max_arg(c, pot, inv_eps, count);
  if (!std::isfinite(m)) return m;
  double sum = 0.0;
  for (std::size_t j = 0; j < count; ++j) sum += std::exp(pot[j] - static_cast<double>(c[j]) * inv_eps - m);
  return m + std::log(sum);
}

// Σ_j exp(shift + pot_j − c_j·inv_eps) and Σ_j of the same times c_j, i.e. a row (or column) sum of the
// plan and its share of ⟨P, C⟩, with the row maximum taken out of the exponent for accuracy.
template <class T>
D2GS_ALWAYS_INLINE void plan_body(const T* c, const double* pot, double shift, double inv_eps, std::size_t count,
                                  bool precise, double* mass, double* cost) {
  const double m = max_arg(c, pot, inv_eps, count);
  double sm = 0.0, sc = 0.0;
  if (precise) {
    for (std::size_t j = 0; j < count; ++j) {
      const double ck = static_cast<double>(c[j]);
      const double p = std::exp(pot[j] - ck * inv_eps - m);
      sm += p;
      sc += p * ck;
    }
  } else {
    v8d acc_mass{}, acc_cost{};
    std::size_t j = 0;
    for (; j + kLanes <= count; j += kLanes) {
      const v8d ck = load8(c + j);
      const v8d p = __builtin_convertvector(exp8(__builtin_convertvector(load8(pot + j) - ck * inv_eps - m, v8f)), v8d);
      acc_mass += p;
      acc_cost += p * ck;
    }
    sm = hsum(acc_mass);
    sc = hsum(acc_cost);
    for (; j < count; ++j) {
      const double ck = static_cast<double>(c[j]);
      const double p = static_cast<double>(exp_core(static_cast<float>(pot[j] - ck * inv_eps - m)));
      sm += p;
      sc += p * ck;
    }
  }
  const double scale = std::isfinite(m) ? std::exp(shift + m) : 0.0;
  *mass = scale * sm;
  *cost = scale * sc;
}

D2GS_VECTOR_CLONES double lse_f32(const float* c, const double* pot, double inv_eps, std::size_t count) {
  return lse_body(c, pot, inv_eps, count);
}
D2GS_VECTOR_CLONES double lse_f64(const double* c, const double* pot, double inv_eps, std::size_t count) {
  return lse_body(c, pot, inv_eps, count);
}
D2GS_VECTOR_CLONES double lse_guess_f32(const float* c, const double* pot, double inv_eps, std::size_t count,
                                        double guess) {
  return lse_guess_body(c, pot, inv_eps, count, guess);
}
D2GS_VECTOR_CLONES double lse_guess_f64(const double* c, const double* pot, double inv_eps, std::size_t count,
                                        double guess) {
  return lse_guess_body(c, pot, inv_eps, count, guess);
}
D2GS_VECTOR_CLONES void plan_f32(const float* c, const double* pot, double shift, double inv_eps, std::size_t count,
                                 bool precise, double* mass, double* cost) {
  plan_body(c, pot, shift, inv_eps, count, precise, mass, cost);
}
D2GS_VECTOR_CLONES void plan_f64(const double* c, const double* pot, double shift, double inv_eps, std::size_t count,
                                 bool precise, double* mass, double* cost) {
  plan_body(c, pot, shift, inv_eps, count, precise, mass, cost);
}

// `guess`: the previous value of this log-sum-exp, or NaN when there is none.
double lse(CostSpan span, const double* pot, double inv_eps, std::size_t count, bool precise, double guess) {
  if (precise)
    return span.f32 ? lse_precise(span.f32, pot, inv_eps, count) : lse_precise(span.f64, pot, inv_eps, count);
  if (std::isfinite(guess)) {
    const double value = span.f32 ? lse_guess_f32(span.f32, pot, inv_eps, count, guess)
                                  : lse_guess_f64(span.f64, pot, inv_eps, count, guess);
    if (!std::isnan(value)) return value;
  }
  return span.f32 ? lse_f32(span.f32, pot, inv_eps, count) : lse_f64(span.f64, pot, inv_eps, count);
}
void plan(CostSpan span, const double* pot, double shift, double inv_eps, std::size_t count, bool precise,
          double* mass, double* cost) {
  if (span.f32)
    plan_f32(span.f32, pot, shift, inv_eps, count, precise, mass, cost);
  else
    plan_f64(span.f64, pot, shift, inv_eps, count, precise, mass, cost);
}

// ---- stabilised-kernel (scaling-form) iterations ----

// out_j = exp(phi + psi_j − c_j·inv_eps) in float; 0 where the exponent is below −87 (no subnormal floats).
template <class T>
D2GS_ALWAYS_INLINE void kernel_row_body(const T* c, const double* psi, double phi, double inv_eps, std::size_t count,
                                        float* out) {
  std::size_t j = 0;
  for (; j + kLanes <= count; j += kLanes) {
    const v8f x = __builtin_convertvector(load8(psi + j) - load8(c + j) * inv_eps + phi, v8f);
    const v8f e = exp8(x);
    const v8f r = x < -87.0f ? v8f{} : e;
    std::memcpy(out + j, &r, sizeof r);
  }
  for (; j < count; ++j) {
    const float x = static_cast<float>(psi[j] - static_cast<double>(c[j]) * inv_eps + phi);
    out[j] = x < -87.0f ? 0.0f : exp_core(x);
  }
}

// 4-lane vectors for the kernel products: GCC keeps 8-lane double accumulators in memory on AVX2, so these loops
// use explicit 4-lane ones (one AVX register), with a fixed summation order.
typedef double v4d __attribute__((vector_size(32)));
typedef float v4f __attribute__((vector_size(16)));
D2GS_ALWAYS_INLINE v4d load4(const float* p) {
  v4f v;
  std::memcpy(&v, p, sizeof v);
  return __builtin_convertvector(v, v4d);
}
D2GS_ALWAYS_INLINE v4d load4(const double* p) {
  v4d v;
  std::memcpy(&v, p, sizeof v);
  return v;
}

// The exact row update and its kernel row in one exp pass: with x_j = psi_j − c_j·inv_eps and M = max_j x_j,
// returns φ = log a − M − log Σ_j e^(x_j − M) (the log-domain update) and writes out_j = e^(x_j − M) · a / Σ, i.e.
// exp(φ + psi_j − c_j·inv_eps); 0 where that is below e^−87 (no subnormals) or x_j − M < −86. Explicit 4-lane
// double / 8-lane float vectors (one AVX register each); the sum's order is fixed.
template <class T>
D2GS_ALWAYS_INLINE double kernel_row_exact_body(const T* c, const double* psi, double log_a, double inv_eps,
                                                std::size_t count, float* out) {
  constexpr double kNegInf = -std::numeric_limits<double>::infinity();
  v4d m0 = v4d{} + kNegInf, m1 = m0;
  std::size_t j = 0;
  for (; j + 8 <= count; j += 8) {
    const v4d x0 = load4(psi + j) - load4(c + j) * inv_eps, x1 = load4(psi + j + 4) - load4(c + j + 4) * inv_eps;
    m0 = x0 > m0 ? x0 : m0;
    m1 = x1 > m1 ? x1 : m1;
  }
  double m = kNegInf;
  for (int k = 0; k < 4; ++k) m = std::max(m, std::max(m0[k], m1[k]));
  for (; j < count; ++j) m = std::max(m, psi[j] - static_cast<double>(c[j]) * inv_eps);
  v4d s0{}, s1{};
  for (j = 0; j + 8 <= count; j += 8) {
    const v4f x0 = __builtin_convertvector(load4(psi + j) - load4(c + j) * inv_eps - m, v4f);
    const v4f x1 = __builtin_convertvector(load4(psi + j + 4) - load4(c + j + 4) * inv_eps - m, v4f);
    const v8f x = __builtin_shufflevector(x0, x1, 0, 1, 2, 3, 4, 5, 6, 7);
    const v8f e = exp8(x);
    s0 += __builtin_convertvector(__builtin_shufflevector(e, e, 0, 1, 2, 3), v4d);
    s1 += __builtin_convertvector(__builtin_shufflevector(e, e, 4, 5, 6, 7), v4d);
    const v8f r = x < -86.0f ? v8f{} : e;
    std::memcpy(out + j, &r, sizeof r);
  }
  const v4d st = s0 + s1;
  double sum = ((st[0] + st[1]) + st[2]) + st[3];
  for (; j < count; ++j) {
    const float x = static_cast<float>(psi[j] - static_cast<double>(c[j]) * inv_eps - m);
    const float e = exp_core(x);
    sum += static_cast<double>(e);
    out[j] = x < -86.0f ? 0.0f : e;
  }
  const double phi = log_a - m - std::log(sum);
  const double scale = std::exp(phi + m);  // a / Σ
  const float scale_f = static_cast<float>(scale);
  const float limit = static_cast<float>(std::exp(-87.0) / scale);
  for (j = 0; j + 8 <= count; j += 8) {
    v8f e;
    std::memcpy(&e, out + j, sizeof e);
    const v8f r = e < limit ? v8f{} : e * scale_f;
    std::memcpy(out + j, &r, sizeof r);
  }
  for (; j < count; ++j) out[j] = out[j] < limit ? 0.0f : out[j] * scale_f;
  return phi;
}

// Σ_j k_j v_j in double: 4 accumulators of 4 lanes over blocks of 16, then ((a0 + a1) + (a2 + a3)) lanes 0..3, then
// the tail (a fixed order).
D2GS_ALWAYS_INLINE double dot_body(const float* k, const double* v, std::size_t count) {
  v4d a0{}, a1{}, a2{}, a3{};
  std::size_t j = 0;
  for (; j + 16 <= count; j += 16) {
    a0 += load4(k + j) * load4(v + j);
    a1 += load4(k + j + 4) * load4(v + j + 4);
    a2 += load4(k + j + 8) * load4(v + j + 8);
    a3 += load4(k + j + 12) * load4(v + j + 12);
  }
  for (; j + 4 <= count; j += 4) a0 += load4(k + j) * load4(v + j);
  const v4d t = (a0 + a1) + (a2 + a3);
  double sum = ((t[0] + t[1]) + t[2]) + t[3];
  for (; j < count; ++j) sum += static_cast<double>(k[j]) * v[j];
  return sum;
}

// y_j += u_r · k_r,j for the given rows in order (the same bits as one row at a time).
D2GS_ALWAYS_INLINE void axpy_body(const float* const* k, const double* u, std::size_t rows, double* y,
                                  std::size_t count) {
  std::size_t j = 0;
  if (rows == 4) {
    const float *k0 = k[0], *k1 = k[1], *k2 = k[2], *k3 = k[3];
    const double u0 = u[0], u1 = u[1], u2 = u[2], u3 = u[3];
    for (; j + 4 <= count; j += 4) {
      v4d acc = load4(y + j);
      acc += load4(k0 + j) * u0;
      acc += load4(k1 + j) * u1;
      acc += load4(k2 + j) * u2;
      acc += load4(k3 + j) * u3;
      std::memcpy(y + j, &acc, sizeof acc);
    }
  } else {
    for (; j + 4 <= count; j += 4) {
      v4d acc = load4(y + j);
      for (std::size_t r = 0; r < rows; ++r) acc += load4(k[r] + j) * u[r];
      std::memcpy(y + j, &acc, sizeof acc);
    }
  }
  for (; j < count; ++j)
    for (std::size_t r = 0; r < rows; ++r) y[j] += static_cast<double>(k[r][j]) * u[r];
}

// A row of the plan P_ij = exp(phi + psi_j − c_ij·inv_eps) as plan_body computes it (row maximum taken out), its
// mass and cost, and col_j += P_ij.
template <class T>
D2GS_ALWAYS_INLINE void plan_row_body(const T* c, const double* pot, double shift, double inv_eps, std::size_t count,
                                      double* col, double* mass, double* cost) {
  const double m = max_arg(c, pot, inv_eps, count);
  if (!std::isfinite(m)) {
    *mass = *cost = 0.0;
    return;
  }
  const double scale = std::exp(shift + m);
  v8d acc_mass{}, acc_cost{};
  std::size_t j = 0;
  for (; j + kLanes <= count; j += kLanes) {
    const v8d ck = load8(c + j);
    const v8d p = __builtin_convertvector(exp8(__builtin_convertvector(load8(pot + j) - ck * inv_eps - m, v8f)), v8d);
    acc_mass += p;
    acc_cost += p * ck;
    v8d y = load8(col + j);
    y += p * scale;
    std::memcpy(col + j, &y, sizeof y);
  }
  double sm = hsum(acc_mass), sc = hsum(acc_cost);
  for (; j < count; ++j) {
    const double ck = static_cast<double>(c[j]);
    const double p = static_cast<double>(exp_core(static_cast<float>(pot[j] - ck * inv_eps - m)));
    sm += p;
    sc += p * ck;
    col[j] += p * scale;
  }
  *mass = scale * sm;
  *cost = scale * sc;
}

D2GS_VECTOR_CLONES void kernel_row_f32(const float* c, const double* psi, double phi, double inv_eps, std::size_t count,
                                       float* out) {
  kernel_row_body(c, psi, phi, inv_eps, count, out);
}
D2GS_VECTOR_CLONES void kernel_row_f64(const double* c, const double* psi, double phi, double inv_eps,
                                       std::size_t count, float* out) {
  kernel_row_body(c, psi, phi, inv_eps, count, out);
}
D2GS_VECTOR_CLONES double kernel_dot(const float* k, const double* v, std::size_t count) {
  return dot_body(k, v, count);
}
D2GS_VECTOR_CLONES void kernel_axpy(const float* const* k, const double* u, std::size_t rows, double* y,
                                    std::size_t count) {
  axpy_body(k, u, rows, y, count);
}
D2GS_VECTOR_CLONES void plan_row_f32(const float* c, const double* pot, double shift, double inv_eps,
                                     std::size_t count, double* col, double* mass, double* cost) {
  plan_row_body(c, pot, shift, inv_eps, count, col, mass, cost);
}
D2GS_VECTOR_CLONES void plan_row_f64(const double* c, const double* pot, double shift, double inv_eps,
                                     std::size_t count, double* col, double* mass, double* cost) {
  plan_row_body(c, pot, shift, inv_eps, count, col, mass, cost);
}
D2GS_VECTOR_CLONES double kernel_row_exact_f32(const float* c, const double* psi, double log_a, double inv_eps,
                                               std::size_t count, float* out) {
  return kernel_row_exact_body(c, psi, log_a, inv_eps, count, out);
}
D2GS_VECTOR_CLONES double kernel_row_exact_f64(const double* c, const double* psi, double log_a, double inv_eps,
                                               std::size_t count, float* out) {
  return kernel_row_exact_body(c, psi, log_a, inv_eps, count, out);
}
double kernel_row_exact(CostSpan span, const double* psi, double log_a, double inv_eps, std::size_t count, float* out) {
  return span.f32 ? kernel_row_exact_f32(span.f32, psi, log_a, inv_eps, count, out)
                  : kernel_row_exact_f64(span.f64, psi, log_a, inv_eps, count, out);
}
void kernel_row(CostSpan span, const double* psi, double phi, double inv_eps, std::size_t count, float* out) {
  if (span.f32) kernel_row_f32(span.f32, psi, phi, inv_eps, count, out);
  else kernel_row_f64(span.f64, psi, phi, inv_eps, count, out);
}
void plan_row(CostSpan span, const double* pot, double shift, double inv_eps, std::size_t count, double* col,
              double* mass, double* cost) {
  if (span.f32) plan_row_f32(span.f32, pot, shift, inv_eps, count, col, mass, cost);
  else plan_row_f64(span.f64, pot, shift, inv_eps, count, col, mass, cost);
}

// One scratch row per thread, sized for either orientation.
struct Scratch {
  std::vector<std::vector<double>> buffers;
  Scratch(int threads, std::size_t size) : buffers(static_cast<std::size_t>(threads), std::vector<double>(size)) {}
  double* get() { return buffers[static_cast<std::size_t>(omp_get_thread_num())].data(); }
};

}  // namespace

namespace sinkhorn_detail {
float fast_exp(float x) { return exp_core(x); }
double log_sum_exp(const float* c, const double* pot, double inv_eps, std::size_t count) {
  return lse_f32(c, pot, inv_eps, count);
}
double log_sum_exp(const double* c, const double* pot, double inv_eps, std::size_t count) {
  return lse_f64(c, pot, inv_eps, count);
}
}  // namespace sinkhorn_detail

// ---- stored cost ----

template <class T>
DenseCostMatrix<T>::DenseCostMatrix(std::size_t n, std::size_t m, std::vector<T> row_major, bool with_columns)
    : n_(n), m_(m), by_row_(std::move(row_major)) {
  if (by_row_.size() != n * m) fail("cost matrix: {} values for a {} x {} matrix", by_row_.size(), n, m);
  if (!with_columns) return;
  by_col_.resize(n * m);
  constexpr std::size_t kBlock = 64;
  const auto blocks = static_cast<std::int64_t>((m + kBlock - 1) / kBlock);
#pragma omp parallel for schedule(static)
  for (std::int64_t bj = 0; bj < blocks; ++bj) {
    const std::size_t j0 = static_cast<std::size_t>(bj) * kBlock, j1 = std::min(m, j0 + kBlock);
    for (std::size_t i0 = 0; i0 < n; i0 += kBlock) {
      const std::size_t i1 = std::min(n, i0 + kBlock);
      for (std::size_t j = j0; j < j1; ++j)
        for (std::size_t i = i0; i < i1; ++i) by_col_[j * n + i] = by_row_[i * m + j];
    }
  }
}

template <class T>
CostSpan DenseCostMatrix<T>::row(std::size_t i, double*) const {
  CostSpan s;
  if constexpr (std::is_same_v<T, float>) s.f32 = by_row_.data() + i * m_;
  else s.f64 = by_row_.data() + i * m_;
  return s;
}

template <class T>
CostSpan DenseCostMatrix<T>::column(std::size_t j, double* scratch) const {
  CostSpan s;
  if (by_col_.empty() && !by_row_.empty()) {  // rows only: gather (strided)
    for (std::size_t i = 0; i < n_; ++i) scratch[i] = static_cast<double>(by_row_[i * m_ + j]);
    s.f64 = scratch;
    return s;
  }
  if constexpr (std::is_same_v<T, float>) s.f32 = by_col_.data() + j * n_;
  else s.f64 = by_col_.data() + j * n_;
  return s;
}

template <class T>
DenseCostMatrix<T> store_cost(const CostMatrix& cost, bool with_columns) {
  const std::size_t n = cost.rows(), m = cost.cols();
  std::vector<T> values(n * m);
  Scratch scratch(omp_get_max_threads(), std::max(n, m));
#pragma omp parallel for schedule(dynamic, 16)
  for (std::int64_t si = 0; si < static_cast<std::int64_t>(n); ++si) {
    const auto i = static_cast<std::size_t>(si);
    const CostSpan s = cost.row(i, scratch.get());
    T* out = values.data() + i * m;
    if (s.f32)
      for (std::size_t j = 0; j < m; ++j) out[j] = static_cast<T>(s.f32[j]);
    else
      for (std::size_t j = 0; j < m; ++j) out[j] = static_cast<T>(s.f64[j]);
  }
  return DenseCostMatrix<T>(n, m, std::move(values), with_columns);
}

template class DenseCostMatrix<float>;
template class DenseCostMatrix<double>;
template DenseCostMatrix<float> store_cost<float>(const CostMatrix&, bool);
template DenseCostMatrix<double> store_cost<double>(const CostMatrix&, bool);

const char* to_string(SinkhornMethod method) {
  switch (method) {
    case SinkhornMethod::LogDomain: return "log-domain";
    case SinkhornMethod::StabilizedKernel: return "kernel";
  }
  return "?";
}

// ---- the solver ----

namespace {
double max_cost_entry(const CostMatrix& cost, int threads) {
  const std::size_t n = cost.rows(), m = cost.cols();
  std::vector<double> row_max(n, 0.0);
  Scratch scratch(threads, std::max(n, m));
#pragma omp parallel for schedule(dynamic, 16) num_threads(threads)
  for (std::int64_t si = 0; si < static_cast<std::int64_t>(n); ++si) {
    const auto i = static_cast<std::size_t>(si);
    const CostSpan s = cost.row(i, scratch.get());
    double mx = 0.0;
    for (std::size_t j = 0; j < m; ++j) mx = std::max(mx, s.f32 ? static_cast<double>(s.f32[j]) : s.f64[j]);
    row_max[i] = mx;
  }
  double mx = 0.0;
  for (const double v : row_max) mx = std::max(mx, v);
  return mx;
}
}  // namespace

// Anderson acceleration (type II, Walker & Ni 2011) of the fixed-point map ψ ↦ G(ψ), G = one plain Sinkhorn
// iteration seen from ψ: with the residuals F_k = G(ψ_k) − ψ_k of the last `depth` iterates,
//   γ = argmin ‖F_k − ΔF γ‖₂,   ψ_{k+1} = G(ψ_k) − ΔG γ
// (ΔF, ΔG: differences of successive residuals and images). The small least-squares problem is solved by its
// normal equations with a relative Tikhonov term; all sums run serially in a fixed order (deterministic). The
// history restarts when the residual's b-weighted L1 norm Σ_j b_j |F_j| exceeds twice the smallest one since the
// last restart (the extrapolation has left the region where the map is nearly linear: the next iterate is then the
// plain step from the best iterate, G(ψ_best), whose residual becomes the new reference), and when the Gram matrix
// is not positive definite in floating point (the plain step ψ_{k+1} = G(ψ_k)). To first order that norm is the L1
// column-marginal error of the plan after the row update (1 − exp(−F_j) ≈ F_j), the mass still misplaced. The
// largest entry of F, which the stopping rule looks at, is the wrong measure here: a group of components with almost
// no mass can move its potentials by a lot while the plan hardly changes, and a safeguard on the largest entry then
// restarts again and again over a detour that costs nothing (docs/benchmarks.md, "IMR: a dual safeguard for the
// accelerated solver").
//
// A second safeguard keeps the dual objective from falling for long. With φ(ψ) the exact row update from ψ, the
// entropic dual at (φ(ψ), ψ) is ε (⟨a, φ(ψ)⟩ + ⟨b, ψ⟩ − 1) (the plan's rows then sum to a), and a plain iteration
// never lowers it (each half is an exact block maximisation). The solver evaluates h(ψ) = ⟨a, φ(ψ)⟩ + ⟨b, ψ⟩ with
// every row update. An extrapolated iterate may lower h (Anderson's path is not monotone, and the detours pay), but
// not below the lowest h of the last `depth` accepted iterates (the non-monotone acceptance rule of Grippo,
// Lampariello & Lucidi 1986; DAAREM, Henderson & Varadhan 2019, likewise lets Anderson-accelerated EM lose a bounded
// amount of its objective): when it does, the history restarts and the next iterate is the plain step from the
// previous iterate, whose h is at least that iterate's. So the lowest h over the window never falls, and an extrapolation that keeps going astray
// costs one iteration and leaves the plain step in its place, instead of a return to the best iterate by the
// residual, which can go back to the same point again and again (a trained horns pair: 2 950 such restarts in
// 10 000 iterations and no convergence, where plain iterations converge in 4 275; docs/imr.md). Measured against
// the previous iterate alone (a monotone rule) the safeguard rejects the small falls of h that lead out of a slow
// drift, and another horns pair then stalls (docs/benchmarks.md, "IMR: a dual safeguard for the accelerated
// solver").
//
// After `max_restarts` restarts in a stage (both safeguards count) the solver iterates plain for the rest of it.
class Anderson {
public:
  // weights: the column marginal b (the residual safeguard's weights), one per potential ψ_k.
  Anderson(std::size_t depth, std::span<const double> weights)
      : depth_(depth), size_(weights.size()), weights_(weights) {}
  // A new stage (potentials rescaled, another ε: the dual values of the last stage do not compare).
  void reset() {
    restart_history();
    extrapolated_ = false;
    window_.clear();
  }
  int restarts() const { return restarts_; }
  // x: the current iterate ψ_k, replaced by ψ_{k+1}; g = G(ψ_k); dual = h(ψ_k), dual_scale = ⟨a, |φ|⟩ + ⟨b, |ψ|⟩
  // (the double sums' rounding is a few ulps of it).
  //
  // A fall of h smaller than kDualNoise is not taken as one: each φ_i comes from a log of a sum of float exps
  // (or of a float kernel), good to ~1e-7 absolute, so h (Σ a = 1) carries noise of that order. Only near
  // convergence are true changes of h that small (a plain step raises it by about ½ Σ b (Δψ)²: 5e-9 at a
  // change of 1e-4), where the residual safeguard and the closing plain iterations decide.
  static constexpr double kDualNoise = 1e-6;
  void step(std::vector<double>& x, const std::vector<double>& g, double dual, double dual_scale) {
    if (depth_ == 0) {
      x = g;
      return;
    }
    // Dual safeguard: the extrapolation lowered h below the lowest of the window: the plain step from the previous
    // iterate (the window's last entry).
    const double slack = kDualNoise + 64.0 * std::numeric_limits<double>::epsilon() * dual_scale;
    if (extrapolated_ && dual < *std::min_element(window_.begin(), window_.end()) - slack) {
      restart_history();
      ++restarts_;
      extrapolated_ = false;
      x = previous_g_;  // G(ψ_{k−1}): h at least that of ψ_{k−1}, which is in the window
      return;
    }
    if (window_.size() == depth_) window_.pop_front();
    window_.push_back(dual);
    extrapolated_ = false;
    if (dg_.empty()) {
      dg_.assign(depth_, std::vector<double>(size_));
      df_.assign(depth_, std::vector<double>(size_));
      previous_g_.resize(size_);
      previous_f_.resize(size_);
      f_.resize(size_);
    }
    double residual = 0.0;  // Σ b_k |F_k|, serial
    for (std::size_t k = 0; k < size_; ++k) {
      f_[k] = g[k] - x[k];
      residual += weights_[k] * std::abs(f_[k]);
    }
    // Residual safeguard: the misplaced mass has doubled over the best since the last restart: the extrapolation
    // has gone astray. Restart the history from the plain step of the best iterate.
    if (residual > 2.0 * best_) {
      restart_history();
      ++restarts_;
      x = best_g_;
      return;
    }
    if (residual < best_) {
      best_ = residual;
      best_g_ = g;
    }
    if (has_previous_) {
      const std::size_t slot = (head_ + count_) % depth_;
      if (count_ == depth_) head_ = (head_ + 1) % depth_;
      else ++count_;
      for (std::size_t k = 0; k < size_; ++k) {
        dg_[slot][k] = g[k] - previous_g_[k];
        df_[slot][k] = f_[k] - previous_f_[k];
      }
    }
    previous_g_ = g;
    previous_f_ = f_;
    has_previous_ = true;
    if (count_ == 0) {
      x = g;
      return;
    }
    // Normal equations (ΔFᵀΔF + λI) γ = ΔFᵀF.
    const std::size_t c = count_;
    std::vector<double> a(c * c), rhs(c);
    for (std::size_t p = 0; p < c; ++p) {
      const std::vector<double>& fp = df_[(head_ + p) % depth_];
      for (std::size_t q = 0; q <= p; ++q) {
        const std::vector<double>& fq = df_[(head_ + q) % depth_];
        double dot = 0.0;
        for (std::size_t k = 0; k < size_; ++k) dot += fp[k] * fq[k];
        a[p * c + q] = a[q * c + p] = dot;
      }
      double dot = 0.0;
      for (std::size_t k = 0; k < size_; ++k) dot += fp[k] * f_[k];
      rhs[p] = dot;
    }
    double trace = 0.0;
    for (std::size_t p = 0; p < c; ++p) trace += a[p * c + p];
    for (std::size_t p = 0; p < c; ++p) a[p * c + p] += 1e-10 * trace / static_cast<double>(c) + 1e-300;
    // Cholesky.
    for (std::size_t p = 0; p < c; ++p) {
      for (std::size_t q = 0; q < p; ++q) {
        double v = a[p * c + q];
        for (std::size_t r = 0; r < q; ++r) v -= a[p * c + r] * a[q * c + r];
        a[p * c + q] = v / a[q * c + q];
      }
      double d = a[p * c + p];
      for (std::size_t r = 0; r < p; ++r) d -= a[p * c + r] * a[p * c + r];
      if (!(d > 0.0)) {  // not positive definite in floating point: restart
        restart_history();
        x = g;
        return;
      }
      a[p * c + p] = std::sqrt(d);
    }
    std::vector<double> gamma(rhs);
    for (std::size_t p = 0; p < c; ++p) {
      for (std::size_t r = 0; r < p; ++r) gamma[p] -= a[p * c + r] * gamma[r];
      gamma[p] /= a[p * c + p];
    }
    for (std::size_t p = c; p-- > 0;) {
      for (std::size_t r = p + 1; r < c; ++r) gamma[p] -= a[r * c + p] * gamma[r];
      gamma[p] /= a[p * c + p];
    }
    for (std::size_t k = 0; k < size_; ++k) {
      double v = g[k];
      for (std::size_t p = 0; p < c; ++p) v -= gamma[p] * dg_[(head_ + p) % depth_][k];
      x[k] = v;
    }
    extrapolated_ = true;
  }

private:
  void restart_history() {
    count_ = 0;
    has_previous_ = false;
    best_ = std::numeric_limits<double>::infinity();  // the next residual is the new reference (no livelock)
  }

  std::size_t depth_, size_, count_ = 0, head_ = 0;
  std::span<const double> weights_;
  int restarts_ = 0;
  bool has_previous_ = false, extrapolated_ = false;  // extrapolated_: the current iterate is an extrapolation
  double best_ = std::numeric_limits<double>::infinity();
  std::deque<double> window_;  // h of the last `depth_` accepted iterates in this stage, oldest first
  std::vector<std::vector<double>> dg_, df_;
  std::vector<double> previous_g_, previous_f_, f_, best_g_;
};

namespace {

// Rows per chunk of the transposed product Kᵀu: each chunk sums its rows into its own column accumulator (in row
// order), and the chunks are added in chunk order, so the sums do not depend on the thread count.
constexpr std::size_t kChunkRows = 256;
constexpr std::size_t kRowBlock = 4;  // rows per fused dot / axpy block (bitwise the same as one at a time)

void kernel_row_precise(CostSpan span, const double* psi, double phi, double inv_eps, std::size_t count, float* out) {
  for (std::size_t j = 0; j < count; ++j) {
    const double c = span.f32 ? static_cast<double>(span.f32[j]) : span.f64[j];
    const double x = psi[j] - c * inv_eps + phi;
    out[j] = x < -87.0 ? 0.0f : static_cast<float>(std::exp(std::min(x, 88.0)));
  }
}

void plan_row_precise(CostSpan span, const double* pot, double shift, double inv_eps, std::size_t count, double* col,
                      double* mass, double* cost) {
  double m = -std::numeric_limits<double>::infinity();
  for (std::size_t j = 0; j < count; ++j)
    m = std::max(m, pot[j] - (span.f32 ? static_cast<double>(span.f32[j]) : span.f64[j]) * inv_eps);
  *mass = *cost = 0.0;
  if (!std::isfinite(m)) return;
  const double scale = std::exp(shift + m);
  double sm = 0.0, sc = 0.0;
  for (std::size_t j = 0; j < count; ++j) {
    const double c = span.f32 ? static_cast<double>(span.f32[j]) : span.f64[j];
    const double p = std::exp(pot[j] - c * inv_eps - m);
    sm += p;
    sc += p * c;
    col[j] += p * scale;
  }
  *mass = scale * sm;
  *cost = scale * sc;
}

// The L1 marginal error of the plan (φ', ψ) whose rows φ' are the exact update from ψ: only its columns are off,
// column j by the factor exp(ψ_j − ψ'_j) with ψ' the exact column update from φ'.
double half_plan_marginal_error(std::span<const double> b, const std::vector<double>& psi,
                                const std::vector<double>& psi_next) {
  double error = 0.0;
  for (std::size_t j = 0; j < psi.size(); ++j) error += b[j] * std::abs(std::expm1(psi[j] - psi_next[j]));
  return error;
}

// Whether an iteration ends its stage: the potentials' change, or (when asked for, in the last stage) the plan's
// marginal error. Intermediate stages keep the change rule: they set up the warm start of the next ε, and a stage
// left with the potentials of low-mass components far off sends Anderson's extrapolation astray in the next.
bool stage_reached(const SinkhornOptions& options, bool last_stage, double change, double tolerance,
                   std::span<const double> b, const std::vector<double>& psi, const std::vector<double>& psi_next) {
  if (change < tolerance) return true;
  return last_stage && options.marginal_tolerance > 0.0 &&
         half_plan_marginal_error(b, psi, psi_next) < options.marginal_tolerance;
}

// The stabilised-kernel solver (SinkhornMethod::StabilizedKernel; see the header). State: the absolute
// log-potentials φ (after the row update) and ψ, the kernel's potentials φ̂ (per row) and ψ̂ (per column), and
// v = exp(ψ − ψ̂). Each iteration, in one pass over K by chunks of rows: s_i = (K v)_i, u_i = a_i / s_i,
// φ_i = φ̂_i + log u_i, y += u_i K_i (the chunk's accumulator); then v_j = b_j / y_j, ψ_j = ψ̂_j + log v_j. It is
// the log-domain iteration written with scalings: the same map, the same fixed point, the same stopping rule.
// What both solvers do on entering the stage at ε: the potentials rescaled so that f = εφ and g = εψ carry
// over from the previous ε, the stage's record started, and its tolerance (the final one in the last stage).
struct StageEntry {
  bool last_stage;
  double inv_eps, tolerance;
};
StageEntry enter_stage(double eps, const std::vector<double>& epsilons, const SinkhornOptions& options,
                       double& eps_prev, std::vector<double>& phi, std::vector<double>& psi, SinkhornResult& result,
                       SinkhornStage& stage) {
  const bool last_stage = eps == epsilons.back();
  const double rescale = eps_prev / eps;
  for (auto& x : phi) x *= rescale;
  for (auto& x : psi) x *= rescale;
  eps_prev = eps;
  result.converged = false;
  stage.epsilon = eps;
  return {last_stage, 1.0 / eps,
          last_stage ? options.tolerance : std::max(options.tolerance, options.stage_tolerance)};
}

// h(ψ) = ⟨a, φ⟩ + ⟨b, ψ⟩ with φ the exact row update from ψ: the entropic dual there, over ε and less its
// constant (the Anderson safeguard's merit); `scale` = ⟨a, |φ|⟩ + ⟨b, |ψ|⟩ bounds its rounding. Serial sums in
// index order (independent of the thread count).
struct DualValue {
  double value = 0.0, scale = 0.0;
};
DualValue dual_value(std::span<const double> a, std::span<const double> b, const std::vector<double>& phi,
                     const std::vector<double>& psi) {
  DualValue h;
  for (std::size_t i = 0; i < phi.size(); ++i) {
    h.value += a[i] * phi[i];
    h.scale += a[i] * std::abs(phi[i]);
  }
  for (std::size_t j = 0; j < psi.size(); ++j) {
    h.value += b[j] * psi[j];
    h.scale += b[j] * std::abs(psi[j]);
  }
  return h;
}

// Anderson restarts allowed per stage (a negative option: no limit).
int anderson_max_restarts(const SinkhornOptions& options) {
  return options.anderson_max_restarts < 0 ? std::numeric_limits<int>::max() : options.anderson_max_restarts;
}

SinkhornResult sinkhorn_kernel(std::span<const double> a, std::span<const double> b, const std::vector<double>& log_a,
                               const std::vector<double>& log_b, const CostMatrix& cost, const SinkhornOptions& options,
                               int threads, const std::vector<double>& epsilons) {
  const std::size_t n = cost.rows(), m = cost.cols();
  const bool precise = options.double_exp;
  const double tau = options.absorb_threshold;
  if (!(tau > 0.0 && tau <= 30.0)) fail("sinkhorn: absorb threshold must be in (0, 30], got {}", tau);
  const std::size_t chunks = (n + kChunkRows - 1) / kChunkRows;
  std::vector<float> kernel(n * m);
  std::vector<double> acc(chunks * m);
  std::vector<double> phi(n, 0.0), psi(m, 0.0), phi_hat(n, 0.0), psi_hat(m, 0.0), v(m, 1.0);
  std::vector<double> dphi(n, 0.0), dpsi(m, 0.0), psi_next(m, 0.0), u(n, 1.0);
  std::vector<unsigned char> refreshed(n, 0), bad_column(m, 0);
  Scratch scratch(threads, std::max(n, m));
  Anderson anderson(static_cast<std::size_t>(std::max(0, options.anderson_depth)), b);
  SinkhornResult result;
  const auto sm = static_cast<std::int64_t>(m), sn = static_cast<std::int64_t>(n);

  // Whole kernel from the current ψ: ψ̂ = ψ, v = 1, and φ̂ the exact row update from ψ (what the next iteration's
  // row half computes; φ itself is left as it is so that the next iteration measures its change), so that u = 1
  // up to rounding. One exp per entry.
  const auto absorb = [&](double inv_eps) {
    psi_hat = psi;
    std::fill(v.begin(), v.end(), 1.0);
#pragma omp parallel for schedule(dynamic, 16) num_threads(threads)
    for (std::int64_t si = 0; si < sn; ++si) {
      const auto i = static_cast<std::size_t>(si);
      const CostSpan row = cost.row(i, scratch.get());
      float* k = kernel.data() + i * m;
      if (precise) {
        phi_hat[i] = log_a[i] - lse(row, psi.data(), inv_eps, m, true, std::numeric_limits<double>::quiet_NaN());
        kernel_row_precise(row, psi_hat.data(), phi_hat[i], inv_eps, m, k);
      } else {
        phi_hat[i] = kernel_row_exact(row, psi_hat.data(), log_a[i], inv_eps, m, k);
      }
    }
  };

  double eps_prev = epsilons.front();
  for (const double eps : epsilons) {
    const auto stage_start = std::chrono::steady_clock::now();
    SinkhornStage stage;
    // Plain names, not a structured binding: clang 14 cannot capture those in lambdas and OpenMP regions.
    const StageEntry entry = enter_stage(eps, epsilons, options, eps_prev, phi, psi, result, stage);
    const bool last_stage = entry.last_stage;
    const double inv_eps = entry.inv_eps, tolerance = entry.tolerance;
    absorb(inv_eps);
    ++stage.absorptions;
    bool accelerate = options.anderson_depth > 0;
    const int max_restarts = anderson_max_restarts(options);
    anderson.reset();
    while (result.iterations < options.max_iterations) {
      // Rows (u, φ) and the chunks of Kᵀu.
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
      for (std::int64_t sc = 0; sc < static_cast<std::int64_t>(chunks); ++sc) {
        const auto c = static_cast<std::size_t>(sc);
        const std::size_t i0 = c * kChunkRows, i1 = std::min(n, i0 + kChunkRows);
        double* y = acc.data() + c * m;
        std::fill(y, y + m, 0.0);
        for (std::size_t b0 = i0; b0 < i1; b0 += kRowBlock) {
          const std::size_t b1 = std::min(i1, b0 + kRowBlock);
          const float* rows[kRowBlock];
          double scal[kRowBlock];
          for (std::size_t i = b0; i < b1; ++i) {
            float* k = kernel.data() + i * m;
            const double s = kernel_dot(k, v.data(), m);
            double updated = 0.0;
            const double log_u = std::log(a[i] / s);
            if (s > 0.0 && std::abs(log_u) <= tau) {
              u[i] = a[i] / s;
              updated = phi_hat[i] + log_u;
              refreshed[i] = 0;
            } else {
              // Scaling out of range (or an empty kernel row): exact log-domain update of this row, and its kernel
              // row recomputed with φ̂_i = φ_i (u_i = 1).
              const CostSpan row = cost.row(i, scratch.get());
              updated = log_a[i] - lse(row, psi.data(), inv_eps, m, precise, std::numeric_limits<double>::quiet_NaN());
              phi_hat[i] = updated;
              if (precise) kernel_row_precise(row, psi_hat.data(), updated, inv_eps, m, k);
              else kernel_row(row, psi_hat.data(), updated, inv_eps, m, k);
              u[i] = 1.0;
              refreshed[i] = 1;
            }
            dphi[i] = std::abs(updated - phi[i]);
            phi[i] = updated;
            rows[i - b0] = k;
            scal[i - b0] = u[i];
          }
          kernel_axpy(rows, scal, b1 - b0, y, m);
        }
      }
      // Columns: sum the chunks in order, v_j = b_j / (Kᵀu)_j.
#pragma omp parallel for schedule(static) num_threads(threads)
      for (std::int64_t sj = 0; sj < sm; ++sj) {
        const auto j = static_cast<std::size_t>(sj);
        double y = 0.0;
        for (std::size_t c = 0; c < chunks; ++c) y += acc[c * m + j];
        bad_column[j] = !(y > 0.0) || !std::isfinite(y);
        psi_next[j] = bad_column[j] ? 0.0 : psi_hat[j] + std::log(b[j] / y);
      }
      // An empty kernel column (every entry below e^−87): the exact log-domain update of that column.
      std::vector<std::int64_t> bad;
      for (std::size_t j = 0; j < m; ++j)
        if (bad_column[j]) bad.push_back(static_cast<std::int64_t>(j));
      if (!bad.empty()) {
#pragma omp parallel for schedule(dynamic, 4) num_threads(threads)
        for (std::int64_t k = 0; k < static_cast<std::int64_t>(bad.size()); ++k) {
          const auto j = static_cast<std::size_t>(bad[static_cast<std::size_t>(k)]);
          psi_next[j] = log_b[j] - lse(cost.column(j, scratch.get()), phi.data(), inv_eps, n, precise,
                                       std::numeric_limits<double>::quiet_NaN());
        }
      }
      for (std::size_t j = 0; j < m; ++j) dpsi[j] = std::abs(psi_next[j] - psi[j]);
      for (const unsigned char r : refreshed) stage.row_refreshes += r;
      ++result.iterations;
      ++stage.iterations;
      double change = 0.0;
      for (const double d : dphi) change = std::max(change, d);
      for (const double d : dpsi) change = std::max(change, d);
      if (!std::isfinite(change)) fail("sinkhorn: the potentials diverged (non-finite values) at iteration {}", result.iterations);
      check_interrupted("during the transport solve");
      result.last_change = change;
      if (options.on_iteration) options.on_iteration(result.iterations, change, tolerance);
      bool done = false;
      if (stage_reached(options, last_stage, change, tolerance, b, psi, psi_next)) {
        if (accelerate && last_stage) {
          accelerate = false;  // the solve ends on plain iterations: the plain solver's stopping rule
          psi.swap(psi_next);
        } else {
          psi.swap(psi_next);
          result.converged = true;
          done = true;
        }
      } else if (accelerate) {
        ++stage.accelerated;
        const int restarts = anderson.restarts();
        const DualValue h = dual_value(a, b, phi, psi);
        anderson.step(psi, psi_next, h.value, h.scale);
        stage.restarts += anderson.restarts() - restarts;
        if (stage.restarts >= max_restarts) accelerate = false;
      } else {
        psi.swap(psi_next);
      }
      if (done) break;
      // New column scalings; recompute the kernel when one leaves [e^−τ, e^τ].
      bool out_of_range = !bad.empty();
      for (std::size_t j = 0; j < m; ++j) {
        const double log_v = psi[j] - psi_hat[j];
        out_of_range = out_of_range || !(std::abs(log_v) <= tau);
        v[j] = std::exp(log_v);
      }
      if (out_of_range) {
        absorb(inv_eps);
        ++stage.absorptions;
      }
    }
    stage.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - stage_start).count();
    result.stages.push_back(stage);
    if (!result.converged) break;
  }
  result.epsilon = eps_prev;
  kernel.clear();
  kernel.shrink_to_fit();

  // Plan marginals and transport cost with the final potentials, by rows (column masses by chunks, in order).
  const double inv_eps = 1.0 / eps_prev;
  std::vector<double> row_mass(n), row_cost(n);
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
  for (std::int64_t sc = 0; sc < static_cast<std::int64_t>(chunks); ++sc) {
    const auto c = static_cast<std::size_t>(sc);
    double* y = acc.data() + c * m;
    std::fill(y, y + m, 0.0);
    for (std::size_t i = c * kChunkRows; i < std::min(n, (c + 1) * kChunkRows); ++i) {
      const CostSpan row = cost.row(i, scratch.get());
      if (precise) plan_row_precise(row, psi.data(), phi[i], inv_eps, m, y, &row_mass[i], &row_cost[i]);
      else plan_row(row, psi.data(), phi[i], inv_eps, m, y, &row_mass[i], &row_cost[i]);
    }
  }
  double total = 0.0, error = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    total += row_cost[i];
    error += std::abs(row_mass[i] - a[i]);
  }
  for (std::size_t j = 0; j < m; ++j) {
    double y = 0.0;
    for (std::size_t c = 0; c < chunks; ++c) y += acc[c * m + j];
    error += std::abs(y - b[j]);
  }
  result.transport_cost = total;
  result.marginal_error = error;
  // A plan whose marginals are far from a and b is no solution, whatever the stopping rule said (an ε too small
  // for the cost's precision: the potentials stop changing in rounding while the plan is wrong).
  if (!(error <= kMaxConvergedMarginalError)) result.converged = false;
  result.f.resize(n);
  result.g.resize(m);
  for (std::size_t i = 0; i < n; ++i) result.f[i] = eps_prev * phi[i];
  for (std::size_t j = 0; j < m; ++j) result.g[j] = eps_prev * psi[j];
  return result;
}

}  // namespace

SinkhornResult sinkhorn(std::span<const double> a, std::span<const double> b, const CostMatrix& cost,
                        const SinkhornOptions& options) {
  const std::size_t n = cost.rows(), m = cost.cols();
  if (a.size() != n || b.size() != m)
    fail("sinkhorn: weights have {} and {} entries for a {} x {} cost", a.size(), b.size(), n, m);
  if (n == 0 || m == 0) fail("sinkhorn: empty problem ({} x {})", n, m);
  if (!(options.epsilon > 0.0)) fail("sinkhorn: epsilon must be positive, got {}", options.epsilon);
  if (!(options.tolerance >= 0.0)) fail("sinkhorn: tolerance must be non-negative, got {}", options.tolerance);
  if (!(options.marginal_tolerance >= 0.0) || !std::isfinite(options.marginal_tolerance))
    fail("sinkhorn: marginal tolerance must be non-negative, got {}", options.marginal_tolerance);
  if (options.max_iterations < 1) fail("sinkhorn: max iterations must be at least 1, got {}", options.max_iterations);
  if (options.anderson_depth < 0) fail("sinkhorn: Anderson depth must be ≥ 0, got {}", options.anderson_depth);
  std::vector<double> log_a(n), log_b(m);
  for (std::size_t i = 0; i < n; ++i) {
    if (!(a[i] > 0.0) || !std::isfinite(a[i])) fail("sinkhorn: weight a[{}] = {} is not positive", i, a[i]);
    log_a[i] = std::log(a[i]);
  }
  for (std::size_t j = 0; j < m; ++j) {
    if (!(b[j] > 0.0) || !std::isfinite(b[j])) fail("sinkhorn: weight b[{}] = {} is not positive", j, b[j]);
    log_b[j] = std::log(b[j]);
  }
  const int threads =
      options.threads > 0
          ? options.threads
          : static_cast<int>(std::clamp<std::size_t>(n * m >> 18, 1, static_cast<std::size_t>(omp_get_max_threads())));
  const bool precise = options.double_exp;

  // ε schedule
  std::vector<double> epsilons;
  if (options.epsilon_scaling) {
    if (!(options.epsilon_factor > 0.0 && options.epsilon_factor < 1.0))
      fail("sinkhorn: epsilon factor must be in (0, 1), got {}", options.epsilon_factor);
    double e = options.epsilon_start > 0.0 ? options.epsilon_start : max_cost_entry(cost, threads);
    if (!std::isfinite(e))
      fail("sinkhorn: the epsilon schedule starts at {} (a cost entry beyond the float range: the components lie too "
           "far apart for an unnormalised cost)", e);
    // A factor next to 1 (or a start far above epsilon) would make millions of stages: refused up front.
    const double stages = std::ceil(std::log(e / options.epsilon) / -std::log(options.epsilon_factor));
    if (stages > kMaxEpsilonStages)
      fail("sinkhorn: epsilon scaling from {:.4g} to {:.4g} by a factor of {} takes {:.0f} stages, more than {} "
           "(choose a smaller factor)", e, options.epsilon, options.epsilon_factor, stages, kMaxEpsilonStages);
    for (; e > options.epsilon * (1.0 + 1e-9); e *= options.epsilon_factor) epsilons.push_back(e);
  }
  epsilons.push_back(options.epsilon);
  if (options.method == SinkhornMethod::StabilizedKernel)
    return sinkhorn_kernel(a, b, log_a, log_b, cost, options, threads, epsilons);

  SinkhornResult result;
  std::vector<double> phi(n, 0.0), psi(m, 0.0), dphi(n, 0.0), dpsi(m, 0.0), psi_next(m, 0.0);
  Scratch scratch(threads, std::max(n, m));
  Anderson anderson(static_cast<std::size_t>(std::max(0, options.anderson_depth)), b);
  double eps_prev = epsilons.front();
  for (const double eps : epsilons) {
    const auto stage_start = std::chrono::steady_clock::now();
    SinkhornStage stage;
    // Plain names, not a structured binding: clang 14 cannot capture those in lambdas and OpenMP regions.
    const StageEntry entry = enter_stage(eps, epsilons, options, eps_prev, phi, psi, result, stage);
    const bool last_stage = entry.last_stage;
    const double inv_eps = entry.inv_eps, tolerance = entry.tolerance;
    bool first = true;  // no previous log-sum-exp at this ε to shift by
    const double nan = std::numeric_limits<double>::quiet_NaN();
    // Anderson acceleration in this stage until, in the last stage, an iteration has reached the tolerance;
    // then plain iterations decide the stop.
    bool accelerate = options.anderson_depth > 0;
    const int max_restarts = anderson_max_restarts(options);
    anderson.reset();
    while (result.iterations < options.max_iterations) {
#pragma omp parallel num_threads(threads)
      {
#pragma omp for schedule(dynamic, 16)
        for (std::int64_t si = 0; si < static_cast<std::int64_t>(n); ++si) {
          const auto i = static_cast<std::size_t>(si);
          const double guess = first ? nan : log_a[i] - phi[i];
          const double updated = log_a[i] - lse(cost.row(i, scratch.get()), psi.data(), inv_eps, m, precise, guess);
          dphi[i] = std::abs(updated - phi[i]);
          phi[i] = updated;
        }
#pragma omp for schedule(dynamic, 16)
        for (std::int64_t sj = 0; sj < static_cast<std::int64_t>(m); ++sj) {
          const auto j = static_cast<std::size_t>(sj);
          const double guess = first ? nan : log_b[j] - psi[j];
          const double updated = log_b[j] - lse(cost.column(j, scratch.get()), phi.data(), inv_eps, n, precise, guess);
          dpsi[j] = std::abs(updated - psi[j]);
          psi_next[j] = updated;
        }
      }
      ++result.iterations;
      ++stage.iterations;
      first = false;
      double change = 0.0;
      for (const double d : dphi) change = std::max(change, d);
      for (const double d : dpsi) change = std::max(change, d);
      if (!std::isfinite(change)) fail("sinkhorn: the potentials diverged (non-finite values) at iteration {}", result.iterations);
      check_interrupted("during the transport solve");
      result.last_change = change;
      if (options.on_iteration) options.on_iteration(result.iterations, change, tolerance);
      if (stage_reached(options, last_stage, change, tolerance, b, psi, psi_next)) {
        if (accelerate && last_stage) {
          // The solve ends on plain iterations: the plain solver's stopping rule.
          accelerate = false;
          psi.swap(psi_next);
          continue;
        }
        psi.swap(psi_next);
        result.converged = true;
        break;
      }
      if (accelerate) {
        ++stage.accelerated;
        const int restarts = anderson.restarts();
        const DualValue h = dual_value(a, b, phi, psi);  // φ is the row update from ψ
        anderson.step(psi, psi_next, h.value, h.scale);  // ψ ← the extrapolation from ψ and its plain update
        stage.restarts += anderson.restarts() - restarts;
        // Extrapolation keeps failing in this stage: plain iterations for the rest of it (never much worse
        // than the plain solver).
        if (stage.restarts >= max_restarts) accelerate = false;
      } else {
        psi.swap(psi_next);
      }
    }
    stage.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - stage_start).count();
    result.stages.push_back(stage);
    if (!result.converged) break;  // out of iterations: later stages are not run
  }
  result.epsilon = eps_prev;

  // Plan marginals and transport cost with the final potentials.
  const double inv_eps = 1.0 / eps_prev;
  std::vector<double> row_mass(n), row_cost(n), col_mass(m), col_cost(m);
#pragma omp parallel num_threads(threads)
  {
#pragma omp for schedule(dynamic, 16)
    for (std::int64_t si = 0; si < static_cast<std::int64_t>(n); ++si) {
      const auto i = static_cast<std::size_t>(si);
      plan(cost.row(i, scratch.get()), psi.data(), phi[i], inv_eps, m, precise, &row_mass[i], &row_cost[i]);
    }
#pragma omp for schedule(dynamic, 16)
    for (std::int64_t sj = 0; sj < static_cast<std::int64_t>(m); ++sj) {
      const auto j = static_cast<std::size_t>(sj);
      plan(cost.column(j, scratch.get()), phi.data(), psi[j], inv_eps, n, precise, &col_mass[j], &col_cost[j]);
    }
  }
  double total = 0.0, error = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    total += row_cost[i];
    error += std::abs(row_mass[i] - a[i]);
  }
  for (std::size_t j = 0; j < m; ++j) error += std::abs(col_mass[j] - b[j]);
  result.transport_cost = total;
  result.marginal_error = error;
  // A plan whose marginals are far from a and b is no solution, whatever the stopping rule said (an ε too small
  // for the cost's precision: the potentials stop changing in rounding while the plan is wrong).
  if (!(error <= kMaxConvergedMarginalError)) result.converged = false;
  result.f.resize(n);
  result.g.resize(m);
  for (std::size_t i = 0; i < n; ++i) result.f[i] = eps_prev * phi[i];
  for (std::size_t j = 0; j < m; ++j) result.g[j] = eps_prev * psi[j];
  return result;
}

}  // namespace d2gs
