#include "d2gs/eval/imr.hpp"

#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>

#include <unistd.h>

#include <fmt/format.h>

#include "d2gs/core/error.hpp"
#include "d2gs/core/vector_clones.hpp"

namespace d2gs {

const char* to_string(ShapeCost shape) {
  return shape == ShapeCost::TaylorBures ? "taylor-bures" : "exact-bures";
}
const char* to_string(CostStorage storage) {
  switch (storage) {
    case CostStorage::StoredFloat: return "stored-float";
    case CostStorage::StoredDouble: return "stored-double";
    case CostStorage::OnTheFly: return "on-the-fly";
  }
  return "?";
}

namespace {

// Bytes a solve keeps per cost entry: the stored cost (row-major, and column-major too for the log-domain
// solver) and the stabilised-kernel solver's float kernel.
double bytes_per_cost_entry(CostStorage storage, bool kernel) {
  const double value = storage == CostStorage::StoredDouble ? 8.0 : 4.0;
  const double copies = storage == CostStorage::OnTheFly ? 0.0 : kernel ? 1.0 : 2.0;
  return value * copies + (kernel ? 4.0 : 0.0);
}

double physical_memory_bytes() {
  const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
  return pages > 0 && page > 0 ? static_cast<double>(pages) * static_cast<double>(page)
                               : std::numeric_limits<double>::infinity();
}

// out[j] = (‖p − X_j‖² + clamp(¼(Σ_k s_k A_k[j] + s_c + A_c[j]), lo, hi)) · inv_scale.
// With the source fixed (a row) s = Σ_i² features and A = Σ_j⁻¹ features; with the target fixed (a column)
// the roles swap. Both give ¼ tr(Σ_j⁻¹ Σ_i²) − ½ tr Σ_i + ¼ tr Σ_j = ¼ tr((Σ_i − Σ_j) Σ_j⁻¹ (Σ_i − Σ_j)).
D2GS_VECTOR_CLONES void taylor_fill(double px, double py, double pz, const double* s, double s_c, const double* x,
                                    const double* y, const double* z, const double* const* a, const double* a_c,
                                    std::size_t count, double lo, double hi, double inv_scale, double* out) {
  const double s0 = s[0], s1 = s[1], s2 = s[2], s3 = s[3], s4 = s[4], s5 = s[5];
  const double *a0 = a[0], *a1 = a[1], *a2 = a[2], *a3 = a[3], *a4 = a[4], *a5 = a[5];
  for (std::size_t j = 0; j < count; ++j) {
    const double dx = px - x[j], dy = py - y[j], dz = pz - z[j];
    const double pos = dx * dx + dy * dy + dz * dz;
    double shape = s0 * a0[j] + s1 * a1[j] + s2 * a2[j] + s3 * a3[j] + s4 * a4[j] + s5 * a5[j] + s_c + a_c[j];
    shape *= 0.25;
    shape = shape < lo ? lo : shape;
    shape = shape > hi ? hi : shape;
    out[j] = (pos + shape) * inv_scale;
  }
}

D2GS_VECTOR_CLONES double position_max(double px, double py, double pz, const double* x, const double* y,
                                       const double* z, std::size_t count) {
  double lanes[8] = {};
  std::size_t j = 0;
  for (; j + 8 <= count; j += 8)
    for (std::size_t k = 0; k < 8; ++k) {
      const double dx = px - x[j + k], dy = py - y[j + k], dz = pz - z[j + k];
      const double v = dx * dx + dy * dy + dz * dz;
      lanes[k] = v > lanes[k] ? v : lanes[k];
    }
  double m = 0.0;
  for (; j < count; ++j) {
    const double dx = px - x[j], dy = py - y[j], dz = pz - z[j];
    m = std::max(m, dx * dx + dy * dy + dz * dz);
  }
  for (const double l : lanes) m = std::max(m, l);
  return m;
}

double lane_sum(const double* v, std::size_t count) {
  double lanes[8] = {};
  std::size_t j = 0;
  for (; j + 8 <= count; j += 8)
    for (std::size_t k = 0; k < 8; ++k) lanes[k] += v[j + k];
  double s = 0.0;
  for (; j < count; ++j) s += v[j];
  for (const double l : lanes) s += l;
  return s;
}

double trace(const glm::dmat3& m) { return m[0][0] + m[1][1] + m[2][2]; }

glm::dmat3 symmetric_sqrt(const glm::dmat3& m) {
  const SymmetricEigen3 eig = symmetric_eigen(m);
  glm::dmat3 scaled = eig.vectors;
  for (int k = 0; k < 3; ++k) scaled[k] *= std::sqrt(std::max(eig.values[k], 0.0));
  return scaled * glm::transpose(eig.vectors);
}

// tr(Σ_i + Σ_j − 2 (Σ_j^½ Σ_i Σ_j^½)^½) with the target's square root precomputed.
double bures_shape(const glm::dmat3& cov_i, double tr_i, const glm::dmat3& sqrt_j, double tr_j) {
  const glm::dmat3 m = sqrt_j * cov_i * sqrt_j;
  const glm::dvec3 ev = symmetric_eigenvalues(0.5 * (m + glm::transpose(m)));
  const double root_trace = std::sqrt(std::max(ev[0], 0.0)) + std::sqrt(std::max(ev[1], 0.0)) +
                            std::sqrt(std::max(ev[2], 0.0));
  return tr_i + tr_j - 2.0 * root_trace;
}

struct ThreadScratch {
  std::vector<std::vector<double>> buffers;
  explicit ThreadScratch(std::size_t size)
      : buffers(static_cast<std::size_t>(omp_get_max_threads()), std::vector<double>(size)) {}
  double* get() { return buffers[static_cast<std::size_t>(omp_get_thread_num())].data(); }
};

}  // namespace

MixtureCost::MixtureCost(const GaussianMixture& source, const GaussianMixture& target, const CostOptions& options)
    : n_(source.size()), m_(target.size()), options_(options) {
  if (n_ == 0 || m_ == 0) fail("IMR cost: empty mixture ({} x {} components)", n_, m_);
  const bool taylor = options.shape == ShapeCost::TaylorBures;
  sx_.resize(n_), sy_.resize(n_), sz_.resize(n_), st_.resize(n_);
  tx_.resize(m_), ty_.resize(m_), tz_.resize(m_), tt_.resize(m_);
  for (auto& v : sq_) v.resize(taylor ? n_ : 0);
  for (auto& v : tp_) v.resize(taylor ? m_ : 0);
  for (std::size_t i = 0; i < n_; ++i) {
    sx_[i] = source.means[i].x, sy_[i] = source.means[i].y, sz_[i] = source.means[i].z;
    const glm::dmat3& c = source.covariances[i];
    if (taylor) {
      const glm::dmat3 q = c * c;
      sq_[0][i] = q[0][0], sq_[1][i] = q[1][1], sq_[2][i] = q[2][2];
      sq_[3][i] = q[1][0] + q[0][1], sq_[4][i] = q[2][0] + q[0][2], sq_[5][i] = q[2][1] + q[1][2];
      st_[i] = -2.0 * trace(c);
    } else {
      st_[i] = trace(c);
    }
  }
  if (!taylor) s_cov_ = source.covariances;
  for (std::size_t j = 0; j < m_; ++j) {
    tx_[j] = target.means[j].x, ty_[j] = target.means[j].y, tz_[j] = target.means[j].z;
    const glm::dmat3& c = target.covariances[j];
    tt_[j] = trace(c);
    if (taylor) {
      const glm::dmat3 p = glm::inverse(c);
      const double values[6] = {p[0][0], p[1][1], p[2][2], 0.5 * (p[1][0] + p[0][1]), 0.5 * (p[2][0] + p[0][2]),
                                0.5 * (p[2][1] + p[1][2])};
      for (int k = 0; k < 6; ++k) {
        if (!std::isfinite(values[k]))
          fail("IMR cost: covariance {} of the target mixture is singular (sanitise the mixture)", j);
        tp_[k][j] = values[k];
      }
    } else {
      t_sqrt_.push_back(symmetric_sqrt(c));
    }
  }

  // Pass over all pairs: the clamp bound (largest position term), then the mean of the clamped cost.
  std::vector<double> row_stat(n_);
#pragma omp parallel for schedule(dynamic, 16)
  for (std::int64_t si = 0; si < static_cast<std::int64_t>(n_); ++si) {
    const auto i = static_cast<std::size_t>(si);
    row_stat[i] = position_max(sx_[i], sy_[i], sz_[i], tx_.data(), ty_.data(), tz_.data(), m_);
  }
  max_position_ = 0.0;
  for (const double v : row_stat) max_position_ = std::max(max_position_, v);
  lo_ = options.clamp_shape ? 0.0 : -std::numeric_limits<double>::infinity();
  hi_ = options.clamp_shape ? max_position_ : std::numeric_limits<double>::infinity();
  scale_ = inv_scale_ = 1.0;
  if (options.normalize) {
    ThreadScratch scratch(m_);
#pragma omp parallel for schedule(dynamic, 16)
    for (std::int64_t si = 0; si < static_cast<std::int64_t>(n_); ++si) {
      const auto i = static_cast<std::size_t>(si);
      double* buffer = scratch.get();
      fill_row(i, buffer);
      row_stat[i] = lane_sum(buffer, m_);
    }
    double total = 0.0;
    for (const double v : row_stat) total += v;
    const double mean = total / (static_cast<double>(n_) * static_cast<double>(m_));
    if (mean == 0.0 && options.clamp_shape) {
      // Every entry is 0 (entries are ≥ 0 when clamped): the mixtures coincide point for point (e.g. the
      // same single Gaussian twice). S = 0 whatever the plan; there is nothing to normalise.
    } else if (!(mean > 0.0) || !std::isfinite(mean)) {
      fail("IMR cost: the mean cost is {}{}; cannot normalise by it (try --no-normalize)", mean,
           options.clamp_shape ? "" : " (without the clamp the shape term may be negative)");
    } else {
      scale_ = mean;
      inv_scale_ = 1.0 / mean;
    }
  }
}

double MixtureCost::raw_entry(std::size_t i, std::size_t j) const {
  const double dx = sx_[i] - tx_[j], dy = sy_[i] - ty_[j], dz = sz_[i] - tz_[j];
  const double pos = dx * dx + dy * dy + dz * dz;
  double shape;
  if (options_.shape == ShapeCost::TaylorBures) {
    shape = 0.0;
    for (int k = 0; k < 6; ++k) shape += sq_[k][i] * tp_[k][j];
    shape = 0.25 * (shape + st_[i] + tt_[j]);
  } else {
    shape = bures_shape(s_cov_[i], st_[i], t_sqrt_[j], tt_[j]);
  }
  shape = std::min(std::max(shape, lo_), hi_);
  return pos + shape;
}

double MixtureCost::entry(std::size_t i, std::size_t j) const { return raw_entry(i, j) * inv_scale_; }

void MixtureCost::fill_row(std::size_t i, double* out) const {
  if (options_.shape == ShapeCost::TaylorBures) {
    const double s[6] = {sq_[0][i], sq_[1][i], sq_[2][i], sq_[3][i], sq_[4][i], sq_[5][i]};
    const double* a[6] = {tp_[0].data(), tp_[1].data(), tp_[2].data(), tp_[3].data(), tp_[4].data(), tp_[5].data()};
    taylor_fill(sx_[i], sy_[i], sz_[i], s, st_[i], tx_.data(), ty_.data(), tz_.data(), a, tt_.data(), m_, lo_, hi_,
                inv_scale_, out);
  } else {
    for (std::size_t j = 0; j < m_; ++j) out[j] = raw_entry(i, j) * inv_scale_;
  }
}

void MixtureCost::fill_column(std::size_t j, double* out) const {
  if (options_.shape == ShapeCost::TaylorBures) {
    // The same products as fill_row with the roles swapped (the factor 2 of the off-diagonals stays on Σ_i²).
    const double s[6] = {tp_[0][j], tp_[1][j], tp_[2][j], tp_[3][j], tp_[4][j], tp_[5][j]};
    const double* a[6] = {sq_[0].data(), sq_[1].data(), sq_[2].data(), sq_[3].data(), sq_[4].data(), sq_[5].data()};
    taylor_fill(tx_[j], ty_[j], tz_[j], s, tt_[j], sx_.data(), sy_.data(), sz_.data(), a, st_.data(), n_, lo_, hi_,
                inv_scale_, out);
  } else {
    for (std::size_t i = 0; i < n_; ++i) out[i] = raw_entry(i, j) * inv_scale_;
  }
}

CostSpan MixtureCost::row(std::size_t i, double* scratch) const {
  fill_row(i, scratch);
  return CostSpan{nullptr, scratch};
}

CostSpan MixtureCost::column(std::size_t j, double* scratch) const {
  fill_column(j, scratch);
  return CostSpan{nullptr, scratch};
}

TransportResult mixture_transport(const GaussianMixture& source, const GaussianMixture& target,
                                  const ImrOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  const bool kernel = options.sinkhorn.method == SinkhornMethod::StabilizedKernel;
  // A solve whose matrices cannot fit in memory is refused before they are filled (the kernel would kill it).
  const double entries = static_cast<double>(source.size()) * static_cast<double>(target.size());
  const double need = entries * bytes_per_cost_entry(options.storage, kernel), have = physical_memory_bytes();
  if (need > have)
    fail("imr: a transport of {} × {} components keeps {:.1f} GiB of matrices ({} cost{}), more than this machine's "
         "{:.1f} GiB of memory: take fewer --samples{}",
         source.size(), target.size(), need / 1073741824.0, to_string(options.storage), kernel ? ", stabilised kernel" : "",
         have / 1073741824.0, options.storage == CostStorage::OnTheFly ? "" : " (or --cost on-the-fly)");
  const MixtureCost cost(source, target, options.cost);
  SinkhornResult solved;
  switch (options.storage) {
    // The stabilised-kernel solver reads the cost by rows only: no column-major copy.
    case CostStorage::StoredFloat:
      solved = sinkhorn(source.weights, target.weights, store_cost<float>(cost, !kernel), options.sinkhorn);
      break;
    case CostStorage::StoredDouble:
      solved = sinkhorn(source.weights, target.weights, store_cost<double>(cost, !kernel), options.sinkhorn);
      break;
    case CostStorage::OnTheFly:
      solved = sinkhorn(source.weights, target.weights, cost, options.sinkhorn);
      break;
  }
  TransportResult t;
  t.scale = cost.scale();
  t.max_position_term = cost.max_position_term();
  t.normalized_cost = solved.transport_cost;
  t.transport_cost = cost.scale() * solved.transport_cost;
  t.iterations = solved.iterations;
  t.marginal_error = solved.marginal_error;
  t.last_change = solved.last_change;
  t.converged = solved.converged;
  t.stages = solved.stages;
  t.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return t;
}

std::string stage_summary(const TransportResult& t) {
  std::string out;
  for (const SinkhornStage& s : t.stages)
    out += fmt::format("{}{:.4g}: {} ({} accelerated, {} restarts{}), {:.2f} s", out.empty() ? "" : "; ", s.epsilon,
                       s.iterations, s.accelerated, s.restarts,
                       s.absorptions > 0 ? fmt::format(", {} absorptions, {} row refreshes", s.absorptions,
                                                       s.row_refreshes)
                                         : std::string(),
                       s.seconds);
  return out;
}

double imr_from_distances(const std::vector<double>& distances) {
  if (distances.empty()) fail("IMR: no model pairs");
  double squares = 0.0, sum = 0.0;
  for (const double d : distances) {
    squares += d * d;
    sum += d;
  }
  if (sum == 0.0)
    fail("IMR: every pair of models is at distance 0 (identical models): ln(Σd²/Σd) is undefined");
  if (!(sum > 0.0)) fail("IMR: the distances sum to {}, the logarithm is undefined", sum);
  return std::log(squares / sum);
}

ImrResult compute_imr(const std::vector<GaussianMixture>& mixtures, const ImrOptions& options,
                      const std::function<void(const std::string&)>& progress) {
  if (mixtures.size() < 2) fail("IMR needs at least 2 models, got {}", mixtures.size());
  ImrResult result;
  if (options.debiased) {
    for (std::size_t k = 0; k < mixtures.size(); ++k) {
      result.self.push_back(mixture_transport(mixtures[k], mixtures[k], options));
      if (progress) {
        progress(fmt::format("S({0},{0}) = {1:.6g} ({2} iterations, {3:.2f} s)", k, result.self.back().transport_cost,
                             result.self.back().iterations, result.self.back().seconds));
        progress("  ε stages: " + stage_summary(result.self.back()));
      }
    }
  }
  std::vector<double> distances, debiased_roots, debiased_values;
  for (std::size_t a = 0; a < mixtures.size(); ++a)
    for (std::size_t b = a + 1; b < mixtures.size(); ++b) {
      ImrPair pair;
      pair.a = a;
      pair.b = b;
      pair.transport = mixture_transport(mixtures[a], mixtures[b], options);
      pair.distance = std::sqrt(std::max(pair.transport.transport_cost, 0.0));
      distances.push_back(pair.distance);
      if (options.debiased) {
        pair.debiased = debiased_divergence(pair.transport.transport_cost, result.self[a].transport_cost,
                                            result.self[b].transport_cost);
        const double clamped = std::max(*pair.debiased, 0.0);
        debiased_values.push_back(clamped);
        debiased_roots.push_back(std::sqrt(clamped));
      }
      if (progress) {
        progress(fmt::format("S({},{}) = {:.6g} ({} iterations, {:.2f} s)", a, b, pair.transport.transport_cost,
                             pair.transport.iterations, pair.transport.seconds));
        progress("  ε stages: " + stage_summary(pair.transport));
      }
      result.pairs.push_back(pair);
    }
  result.imr = imr_from_distances(distances);
  if (options.debiased) {
    double sum_roots = 0.0, sum_values = 0.0;
    for (std::size_t k = 0; k < debiased_roots.size(); ++k) {
      sum_roots += debiased_roots[k];
      sum_values += debiased_values[k];
    }
    if (sum_roots > 0.0) result.imr_debiased = std::log(sum_values / sum_roots);
  }
  return result;
}

}  // namespace d2gs
