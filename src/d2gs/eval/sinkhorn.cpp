#include "d2gs/eval/sinkhorn.hpp"

#include <omp.h>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <type_traits>

#include "d2gs/core/error.hpp"
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
DenseCostMatrix<T>::DenseCostMatrix(std::size_t n, std::size_t m, std::vector<T> row_major)
    : n_(n), m_(m), by_row_(std::move(row_major)) {
  if (by_row_.size() != n * m) fail("cost matrix: {} values for a {} x {} matrix", by_row_.size(), n, m);
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
CostSpan DenseCostMatrix<T>::column(std::size_t j, double*) const {
  CostSpan s;
  if constexpr (std::is_same_v<T, float>) s.f32 = by_col_.data() + j * n_;
  else s.f64 = by_col_.data() + j * n_;
  return s;
}

template <class T>
DenseCostMatrix<T> store_cost(const CostMatrix& cost) {
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
  return DenseCostMatrix<T>(n, m, std::move(values));
}

template class DenseCostMatrix<float>;
template class DenseCostMatrix<double>;
template DenseCostMatrix<float> store_cost<float>(const CostMatrix&);
template DenseCostMatrix<double> store_cost<double>(const CostMatrix&);

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
// history restarts when the largest entry of the residual exceeds twice the smallest one in this stage (the
// extrapolation has left the region where the map is nearly linear: the next iterate is then the plain step from
// the best iterate, G(ψ_best), whose residual becomes the new reference), and when the Gram matrix is not
// positive definite in floating point (the plain step ψ_{k+1} = G(ψ_k)). After 5 safeguard restarts in a stage
// the solver iterates plain for the rest of the stage.
class Anderson {
public:
  Anderson(std::size_t depth, std::size_t size) : depth_(depth), size_(size) {}
  void reset() {
    count_ = 0;
    has_previous_ = false;
    best_ = std::numeric_limits<double>::infinity();
  }
  int restarts() const { return restarts_; }
  // x: the current iterate ψ_k, replaced by ψ_{k+1}; g = G(ψ_k).
  void step(std::vector<double>& x, const std::vector<double>& g) {
    if (depth_ == 0) {
      x = g;
      return;
    }
    if (dg_.empty()) {
      dg_.assign(depth_, std::vector<double>(size_));
      df_.assign(depth_, std::vector<double>(size_));
      previous_g_.resize(size_);
      previous_f_.resize(size_);
      f_.resize(size_);
    }
    double largest = 0.0;
    for (std::size_t k = 0; k < size_; ++k) {
      f_[k] = g[k] - x[k];
      largest = std::max(largest, std::abs(f_[k]));
    }
    // Safeguard: the largest residual entry (what the stopping rule looks at) has doubled over the best in this
    // stage: the extrapolation has gone astray. Restart the history from the plain step of the best iterate.
    if (largest > 2.0 * best_) {
      count_ = 0;
      has_previous_ = false;
      ++restarts_;
      x = best_g_;
      best_ = std::numeric_limits<double>::infinity();  // the next residual is the new reference (no livelock)
      return;
    }
    if (largest < best_) {
      best_ = largest;
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
        reset();
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
  }

private:
  std::size_t depth_, size_, count_ = 0, head_ = 0;
  int restarts_ = 0;
  bool has_previous_ = false;
  double best_ = std::numeric_limits<double>::infinity();
  std::vector<std::vector<double>> dg_, df_;
  std::vector<double> previous_g_, previous_f_, f_, best_g_;
};

SinkhornResult sinkhorn(std::span<const double> a, std::span<const double> b, const CostMatrix& cost,
                        const SinkhornOptions& options) {
  const std::size_t n = cost.rows(), m = cost.cols();
  if (a.size() != n || b.size() != m)
    fail("sinkhorn: weights have {} and {} entries for a {} x {} cost", a.size(), b.size(), n, m);
  if (n == 0 || m == 0) fail("sinkhorn: empty problem ({} x {})", n, m);
  if (!(options.epsilon > 0.0)) fail("sinkhorn: epsilon must be positive, got {}", options.epsilon);
  if (!(options.tolerance >= 0.0)) fail("sinkhorn: tolerance must be non-negative, got {}", options.tolerance);
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
    for (; e > options.epsilon * (1.0 + 1e-9); e *= options.epsilon_factor) epsilons.push_back(e);
  }
  epsilons.push_back(options.epsilon);

  SinkhornResult result;
  std::vector<double> phi(n, 0.0), psi(m, 0.0), dphi(n, 0.0), dpsi(m, 0.0), psi_next(m, 0.0);
  Scratch scratch(threads, std::max(n, m));
  Anderson anderson(static_cast<std::size_t>(std::max(0, options.anderson_depth)), m);
  double eps_prev = epsilons.front();
  for (const double eps : epsilons) {
    const auto stage_start = std::chrono::steady_clock::now();
    const bool last_stage = eps == epsilons.back();
    const double inv_eps = 1.0 / eps;
    const double tolerance = last_stage ? options.tolerance : std::max(options.tolerance, options.stage_tolerance);
    const double rescale = eps_prev / eps;  // keep f = εφ, g = εψ across stages
    for (auto& v : phi) v *= rescale;
    for (auto& v : psi) v *= rescale;
    eps_prev = eps;
    result.converged = false;
    SinkhornStage stage;
    stage.epsilon = eps;
    bool first = true;  // no previous log-sum-exp at this ε to shift by
    const double nan = std::numeric_limits<double>::quiet_NaN();
    // Anderson acceleration in this stage until, in the last stage, an iteration has reached the tolerance;
    // then plain iterations decide the stop.
    bool accelerate = options.anderson_depth > 0;
    constexpr int kMaxRestarts = 5;
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
      result.last_change = change;
      if (options.on_iteration) options.on_iteration(result.iterations, change, tolerance);
      if (change < tolerance) {
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
        anderson.step(psi, psi_next);  // ψ ← the extrapolation from ψ and its plain update
        stage.restarts += anderson.restarts() - restarts;
        // Extrapolation keeps failing in this stage: plain iterations for the rest of it (never much worse
        // than the plain solver).
        if (stage.restarts >= kMaxRestarts) accelerate = false;
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
  result.f.resize(n);
  result.g.resize(m);
  for (std::size_t i = 0; i < n; ++i) result.f[i] = eps_prev * phi[i];
  for (std::size_t j = 0; j < m; ++j) result.g[j] = eps_prev * psi[j];
  return result;
}

}  // namespace d2gs
