#include "d2gs/eval/gaussian_mixture.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <numeric>
#include <utility>

#include "d2gs/core/error.hpp"
#include "d2gs/render/activations.hpp"

namespace d2gs {

glm::dmat3 quaternion_to_rotation(double w, double x, double y, double z) {
  const double norm = std::sqrt(w * w + x * x + y * y + z * z);
  if (!(norm > 0.0) || !std::isfinite(norm)) return glm::dmat3(1.0);
  w /= norm;
  x /= norm;
  y /= norm;
  z /= norm;
  glm::dmat3 r;  // glm is column-major: r[col][row]
  r[0][0] = 1 - 2 * (y * y + z * z);
  r[1][0] = 2 * (x * y - w * z);
  r[2][0] = 2 * (x * z + w * y);
  r[0][1] = 2 * (x * y + w * z);
  r[1][1] = 1 - 2 * (x * x + z * z);
  r[2][1] = 2 * (y * z - w * x);
  r[0][2] = 2 * (x * z - w * y);
  r[1][2] = 2 * (y * z + w * x);
  r[2][2] = 1 - 2 * (x * x + y * y);
  return r;
}

glm::dmat3 gaussian_covariance(const Gaussians& model, std::size_t i) {
  const float* q = &model.quats[i * 4];
  const glm::dmat3 r = quaternion_to_rotation(q[0], q[1], q[2], q[3]);
  glm::dmat3 rs;
  for (int c = 0; c < 3; ++c) rs[c] = r[c] * std::exp(static_cast<double>(model.log_scales[i * 3 + c]));
  return rs * glm::transpose(rs);
}

std::vector<double> imr_depths(const Gaussians& model, const Camera& reference) {
  const glm::dvec3 axis = reference.R_world_to_cam[2];  // third column of R_w2c
  std::vector<double> depths(model.size());
  for (std::size_t i = 0; i < depths.size(); ++i) {
    const glm::dvec3 x(model.means[i * 3], model.means[i * 3 + 1], model.means[i * 3 + 2]);
    depths[i] = std::abs(glm::dot(x, axis)) + 1e-6;
  }
  return depths;
}

std::vector<std::size_t> depth_strata_indices(const std::vector<double>& depths, std::size_t samples,
                                              std::size_t phase) {
  const std::size_t count = depths.size();
  if (count == 0) return {};
  std::vector<std::size_t> order(count);
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return depths[a] < depths[b]; });
  const std::size_t n = std::max<std::size_t>(1, std::min(samples, count));
  const std::size_t b = count / n;
  const std::size_t cut1 = count / 3, cut2 = 2 * count / 3;
  const std::size_t strides[3] = {b + 2, b, b > 2 ? b - 2 : 1};
  const std::size_t begins[3] = {0, cut1, cut2}, ends[3] = {cut1, cut2, count};
  std::vector<std::size_t> selected;
  for (int third = 0; third < 3; ++third)
    for (std::size_t r = begins[third] + phase % strides[third]; r < ends[third]; r += strides[third])
      selected.push_back(order[r]);
  return selected;
}

double covariance_eigenvalue_floor(const std::vector<glm::dmat3>& covariances) {
  double largest = 0.0;
  for (const auto& c : covariances) largest = std::max({largest, c[0][0], c[1][1], c[2][2]});
  const double root = 1e-3 * std::sqrt(largest);
  return root * root;
}

SymmetricEigen3 symmetric_eigen(const glm::dmat3& m) {
  double a[3][3];
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) a[r][c] = 0.5 * (m[c][r] + m[r][c]);
  double v[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  static constexpr int kPairs[3][2] = {{0, 1}, {0, 2}, {1, 2}};
  for (int sweep = 0; sweep < 64; ++sweep) {
    const double off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
    const double diag = a[0][0] * a[0][0] + a[1][1] * a[1][1] + a[2][2] * a[2][2];
    if (off == 0.0 || off <= 1e-36 * diag) break;
    for (const auto& pq : kPairs) {
      const int p = pq[0], q = pq[1];
      const double apq = a[p][q];
      if (apq == 0.0) continue;
      const double theta = (a[q][q] - a[p][p]) / (2.0 * apq);
      double t;
      if (std::abs(theta) > 1e150) {
        t = 0.5 / theta;
      } else {
        t = 1.0 / (std::abs(theta) + std::sqrt(theta * theta + 1.0));
        if (theta < 0) t = -t;
      }
      const double c = 1.0 / std::sqrt(t * t + 1.0), s = t * c;
      for (int k = 0; k < 3; ++k) {  // A ← A P (columns p, q)
        const double akp = a[k][p], akq = a[k][q];
        a[k][p] = c * akp - s * akq;
        a[k][q] = s * akp + c * akq;
      }
      for (int k = 0; k < 3; ++k) {  // A ← Pᵀ A (rows p, q)
        const double apk = a[p][k], aqk = a[q][k];
        a[p][k] = c * apk - s * aqk;
        a[q][k] = s * apk + c * aqk;
      }
      a[p][q] = a[q][p] = 0.0;
      for (int k = 0; k < 3; ++k) {  // V ← V P
        const double vkp = v[k][p], vkq = v[k][q];
        v[k][p] = c * vkp - s * vkq;
        v[k][q] = s * vkp + c * vkq;
      }
    }
  }
  int idx[3] = {0, 1, 2};
  std::sort(idx, idx + 3, [&](int x, int y) { return a[x][x] < a[y][y]; });
  SymmetricEigen3 out;
  for (int k = 0; k < 3; ++k) {
    out.values[k] = a[idx[k]][idx[k]];
    for (int r = 0; r < 3; ++r) out.vectors[k][r] = v[r][idx[k]];
  }
  return out;
}

glm::dvec3 symmetric_eigenvalues(const glm::dmat3& m) {
  const double a00 = m[0][0], a11 = m[1][1], a22 = m[2][2];
  const double a01 = m[1][0], a02 = m[2][0], a12 = m[2][1];
  const double p1 = a01 * a01 + a02 * a02 + a12 * a12;
  if (p1 == 0.0) {
    glm::dvec3 d(a00, a11, a22);
    if (d.x > d.y) std::swap(d.x, d.y);
    if (d.y > d.z) std::swap(d.y, d.z);
    if (d.x > d.y) std::swap(d.x, d.y);
    return d;
  }
  const double q = (a00 + a11 + a22) / 3.0;
  const double b00 = a00 - q, b11 = a11 - q, b22 = a22 - q;
  const double p2 = b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * p1;
  const double p = std::sqrt(p2 / 6.0);
  const double det = b00 * (b11 * b22 - a12 * a12) - a01 * (a01 * b22 - a12 * a02) +
                     a02 * (a01 * a12 - b11 * a02);
  const double r = std::clamp(det / (2.0 * p * p * p), -1.0, 1.0);
  const double phi = std::acos(r) / 3.0;
  const double largest = q + 2.0 * p * std::cos(phi);
  const double smallest = q + 2.0 * p * std::cos(phi + 2.0 * std::numbers::pi / 3.0);
  const double middle = 3.0 * q - largest - smallest;
  return {smallest, std::clamp(middle, smallest, largest), largest};
}

std::size_t sanitize_covariances(std::vector<glm::dmat3>& covariances, double floor) {
  std::size_t clamped = 0;
  for (auto& c : covariances) {
    c = 0.5 * (c + glm::transpose(c));
    const SymmetricEigen3 eig = symmetric_eigen(c);
    if (eig.values[0] >= floor) continue;
    glm::dmat3 scaled = eig.vectors;
    for (int k = 0; k < 3; ++k) scaled[k] *= std::max(eig.values[k], floor);
    c = scaled * glm::transpose(eig.vectors);
    c = 0.5 * (c + glm::transpose(c));
    ++clamped;
  }
  return clamped;
}

GaussianMixture mixture_from_model(const Gaussians& model, const std::vector<std::size_t>& indices,
                                   bool sanitize) {
  model.validate();
  GaussianMixture mix;
  mix.means.reserve(indices.size());
  mix.covariances.reserve(indices.size());
  mix.weights.reserve(indices.size());
  double total = 0.0;
  for (const std::size_t i : indices) {
    if (i >= model.size()) fail("mixture: Gaussian index {} is outside the model ({} Gaussians)", i, model.size());
    mix.means.emplace_back(model.means[i * 3], model.means[i * 3 + 1], model.means[i * 3 + 2]);
    mix.covariances.push_back(gaussian_covariance(model, i));
    const double alpha = sigmoid(static_cast<double>(model.opacity_logits[i]));
    mix.weights.push_back(alpha);
    total += alpha;
  }
  if (mix.empty()) fail("mixture: the model has no Gaussians");
  if (!(total > 0.0) || !std::isfinite(total)) fail("mixture: the opacities sum to {}, not a positive number", total);
  for (auto& w : mix.weights) w /= total;
  if (sanitize) sanitize_covariances(mix.covariances, covariance_eigenvalue_floor(mix.covariances));
  return mix;
}

namespace {
std::vector<std::size_t> all_indices(std::size_t count) {
  std::vector<std::size_t> all;
  all.reserve(count);
  for (std::size_t i = 0; i < count; ++i) all.push_back(i);
  return all;
}
}  // namespace

GaussianMixture mixture_from_model(const Gaussians& model) {
  return mixture_from_model(model, all_indices(model.size()), false);
}

GaussianMixture mixture_from_model(const Gaussians& model, const Camera& reference,
                                   const MixtureOptions& options) {
  model.validate();
  const std::vector<std::size_t> indices =
      options.samples == 0 ? all_indices(model.size())
                           : depth_strata_indices(imr_depths(model, reference), options.samples, options.phase);
  return mixture_from_model(model, indices, options.sanitize);
}

}  // namespace d2gs
