// The IMR cost, transport and metric (method.md §7 steps 3-6) on hand-built mixtures.
#include <cmath>
#include <cstdio>
#include <random>

#include <gtest/gtest.h>

#include "d2gs/core/error.hpp"
#include "d2gs/eval/imr.hpp"

namespace d2gs {
namespace {

GaussianMixture random_mixture(std::size_t n, unsigned seed, double spacing = 1.0) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n01;
  std::uniform_real_distribution<double> u(0.1, 1.0);
  GaussianMixture mix;
  double total = 0;
  for (std::size_t i = 0; i < n; ++i) {
    mix.means.emplace_back(spacing * n01(rng), spacing * n01(rng), 4.0 + spacing * n01(rng));
    const glm::dmat3 r = quaternion_to_rotation(n01(rng), n01(rng), n01(rng), n01(rng));
    const glm::dvec3 s(0.05 * u(rng), 0.05 * u(rng), 0.05 * u(rng));
    glm::dmat3 rs = r;
    for (int k = 0; k < 3; ++k) rs[k] *= s[k];
    mix.covariances.push_back(rs * glm::transpose(rs));
    mix.weights.push_back(u(rng));
    total += mix.weights.back();
  }
  for (auto& w : mix.weights) w /= total;
  return mix;
}

double taylor_shape(const glm::dmat3& si, const glm::dmat3& sj) {
  const glm::dmat3 d = si - sj;
  const glm::dmat3 m = d * glm::inverse(sj) * d;
  return 0.25 * (m[0][0] + m[1][1] + m[2][2]);
}

TEST(ImrCost, EntriesMatchTheFormulaAndRowsColumnsAgree) {
  const GaussianMixture a = random_mixture(40, 1), b = random_mixture(30, 2);
  CostOptions raw;
  raw.clamp_shape = false;
  raw.normalize = false;
  const MixtureCost c(a, b, raw);
  double max_pos = 0, sum = 0, sum_clamped = 0;
  for (std::size_t i = 0; i < 40; ++i)
    for (std::size_t j = 0; j < 30; ++j) {
      const glm::dvec3 d = a.means[i] - b.means[j];
      max_pos = std::max(max_pos, glm::dot(d, d));
    }
  for (std::size_t i = 0; i < 40; ++i)
    for (std::size_t j = 0; j < 30; ++j) {
      const glm::dvec3 d = a.means[i] - b.means[j];
      const double shape = taylor_shape(a.covariances[i], b.covariances[j]);
      const double expected = glm::dot(d, d) + shape;
      EXPECT_NEAR(c.entry(i, j), expected, 1e-12 * (1 + expected));
      sum += expected;
      sum_clamped += glm::dot(d, d) + std::clamp(shape, 0.0, max_pos);
    }
  EXPECT_DOUBLE_EQ(c.max_position_term(), max_pos);
  EXPECT_EQ(c.scale(), 1.0);
  const MixtureCost release(a, b);  // clamp + mean normalisation
  EXPECT_NEAR(release.scale(), sum_clamped / 1200.0, 1e-12 * release.scale());
  std::vector<double> row(40), col(40);
  for (std::size_t i = 0; i < 40; i += 7) {
    const CostSpan s = release.row(i, row.data());
    for (std::size_t j = 0; j < 30; ++j) EXPECT_DOUBLE_EQ(s.f64[j], release.entry(i, j));
  }
  for (std::size_t j = 0; j < 30; j += 7) {
    const CostSpan s = release.column(j, col.data());
    for (std::size_t i = 0; i < 40; ++i) EXPECT_NEAR(s.f64[i], release.entry(i, j), 1e-15 * (1 + s.f64[i]));
  }
}

TEST(ImrCost, ExactBuresCommutingCaseAndTaylorLimit) {
  // Commuting covariances: Bures shape term = Σ_k (√λ_k − √μ_k)².
  GaussianMixture a, b;
  a.means = {glm::dvec3(0.0)};
  b.means = {glm::dvec3(1, 2, 2)};
  a.weights = b.weights = {1.0};
  a.covariances = {glm::dmat3(glm::dvec3(4, 0, 0), glm::dvec3(0, 1, 0), glm::dvec3(0, 0, 0.25))};
  b.covariances = {glm::dmat3(glm::dvec3(1, 0, 0), glm::dvec3(0, 9, 0), glm::dvec3(0, 0, 0.25))};
  CostOptions bures;
  bures.shape = ShapeCost::ExactBures;
  bures.normalize = false;
  EXPECT_NEAR(MixtureCost(a, b, bures).entry(0, 0), 9.0 + 1.0 + 4.0, 1e-12);
  // Near-identical covariances with the same axes: the Taylor form and the Bures term agree to second
  // order ((√a − √b)² ≈ (a − b)²/(4b) per axis). (With different axes they do not: the Bures metric's
  // second-order term is ½ tr(D X), X Σ + Σ X = D, which is ¼ tr(D Σ⁻¹ D) only when D and Σ commute.)
  const glm::dmat3 r = quaternion_to_rotation(0.7, 0.2, 0.1, -0.4);
  const glm::dmat3 base = r * glm::dmat3(glm::dvec3(2, 0, 0), glm::dvec3(0, 1, 0), glm::dvec3(0, 0, 0.5)) *
                          glm::transpose(r);
  const glm::dmat3 pert = r * glm::dmat3(glm::dvec3(1e-3, 0, 0), glm::dvec3(0, -2e-3, 0), glm::dvec3(0, 0, 1e-3)) *
                          glm::transpose(r);
  a.covariances = {base + pert};
  b.covariances = {base};
  b.means = a.means;
  CostOptions taylor = bures;
  taylor.shape = ShapeCost::TaylorBures;
  taylor.clamp_shape = bures.clamp_shape = false;
  const double t = MixtureCost(a, b, taylor).entry(0, 0), e = MixtureCost(a, b, bures).entry(0, 0);
  EXPECT_GT(e, 0);
  EXPECT_NEAR(t, e, 0.01 * e);
}

TEST(Imr, IdenticalModelsGiveTheEntropicFloorAndZeroDebiased) {
  const GaussianMixture a = random_mixture(300, 3);
  ImrOptions o;
  o.debiased = true;
  const ImrResult r = compute_imr({a, a}, o);
  ASSERT_EQ(r.pairs.size(), 1u);
  const TransportResult& t = r.pairs[0].transport;
  EXPECT_TRUE(t.converged);
  EXPECT_GT(t.transport_cost, 0.0);  // entropic blur: not 0 for identical models
  EXPECT_EQ(t.transport_cost, r.self[0].transport_cost);
  EXPECT_EQ(*r.pairs[0].debiased, 0.0);
  EXPECT_FALSE(r.imr_debiased.has_value());  // Σ sqrt(D) = 0: undefined
  EXPECT_NEAR(r.imr, std::log(r.pairs[0].distance), 1e-15);
  // The floor shrinks with ε (about linearly for small ε).
  ImrOptions small = o;
  small.debiased = false;
  small.sinkhorn.epsilon = 0.01;
  const TransportResult t_small = mixture_transport(a, a, small);
  EXPECT_LT(t_small.transport_cost, 0.2 * t.transport_cost);
}

TEST(Imr, AcceleratedSolverMatchesThePlainOne) {
  // The accelerated solver (Anderson, ε ÷4 per stage) against the default (plain, ε halved): same S.
  for (const unsigned seed : {5u, 6u}) {
    const GaussianMixture a = random_mixture(400, seed), b = random_mixture(380, seed + 100);
    ImrOptions fast;
    use_accelerated_solver(fast.sinkhorn);
    fast.sinkhorn.method = SinkhornMethod::LogDomain;
    ImrOptions plain;  // the default before the stabilised kernel
    use_plain_solver(plain.sinkhorn);
    plain.sinkhorn.method = SinkhornMethod::LogDomain;
    const ImrOptions kernel;  // the default: stabilised kernel, accelerated
    ImrOptions tight = plain;  // the converged value
    tight.sinkhorn.tolerance = 1e-6;
    tight.storage = CostStorage::StoredDouble;
    const TransportResult f = mixture_transport(a, b, fast), p = mixture_transport(a, b, plain),
                          t = mixture_transport(a, b, tight);
    ASSERT_TRUE(f.converged);
    ASSERT_TRUE(p.converged);
    ASSERT_TRUE(t.converged);
    EXPECT_NEAR(f.transport_cost, t.transport_cost, 1e-5 * t.transport_cost);
    const TransportResult k = mixture_transport(a, b, kernel);
    ASSERT_TRUE(k.converged);
    EXPECT_NEAR(k.transport_cost, t.transport_cost, 1e-5 * t.transport_cost);
    EXPECT_LT(k.marginal_error, 1e-4);
    EXPECT_NEAR(f.transport_cost, p.transport_cost, 1e-4 * p.transport_cost);
    EXPECT_LE(f.iterations, p.iterations);
    EXPECT_LT(f.marginal_error, 1e-4);
  }
  // Identical models converge to the floor with the accelerated solver too.
  const GaussianMixture a = random_mixture(350, 8);
  ImrOptions plain;
  use_plain_solver(plain.sinkhorn);
  plain.sinkhorn.method = SinkhornMethod::LogDomain;
  plain.sinkhorn.tolerance = 1e-6;
  plain.storage = CostStorage::StoredDouble;
  ImrOptions fast;
  fast.sinkhorn.method = SinkhornMethod::LogDomain;
  const ImrOptions kernel;  // the default
  const TransportResult self_plain = mixture_transport(a, a, plain);
  for (const ImrOptions* o : {static_cast<const ImrOptions*>(&fast), &kernel}) {
    const TransportResult self_fast = mixture_transport(a, a, *o);
    EXPECT_TRUE(self_fast.converged);
    EXPECT_LT(self_fast.last_change, 1e-4);
    EXPECT_GT(self_fast.transport_cost, 0.0);
    EXPECT_NEAR(self_fast.transport_cost, self_plain.transport_cost, 1e-5 * self_plain.transport_cost);
    std::printf("[ floor    ] identical models, %s: S = %.8g, %d iterations, marginal error %.1e\n",
                to_string(o->sinkhorn.method), self_fast.transport_cost, self_fast.iterations, self_fast.marginal_error);
  }
}

TEST(Imr, ShiftedCopyCostsTheSquaredShift) {
  // Translation by v is an optimal map for the quadratic cost, and for matched components the shape term
  // is 0, so the unregularised transport cost is exactly ‖v‖². With well separated components (spacing
  // 1 ≫ ‖v‖ = 0.05) and a small ε on the raw cost (no normalisation; ε = 1e-5, well below the cost gap
  // 2·spacing·‖v‖ between matchings) the entropic plan is essentially that matching.
  const GaussianMixture a = random_mixture(200, 4, 1.0);
  GaussianMixture b = a;
  const glm::dvec3 v(0.03, -0.04, 0.0);
  for (auto& m : b.means) m += v;
  ImrOptions o;
  o.cost.normalize = false;
  o.sinkhorn.epsilon = 1e-5;
  o.sinkhorn.epsilon_scaling = true;
  o.sinkhorn.tolerance = 1e-6;
  o.sinkhorn.max_iterations = 100000;
  o.storage = CostStorage::StoredDouble;
  const TransportResult t = mixture_transport(a, b, o);
  EXPECT_TRUE(t.converged);
  EXPECT_NEAR(t.transport_cost, glm::dot(v, v), 0.01 * glm::dot(v, v));
  // With normalisation the same: S is scale·⟨P, C̃⟩, ε now relative to the mean cost.
  o.cost.normalize = true;
  o.sinkhorn.epsilon = 1e-5 / 20.0;
  const TransportResult tn = mixture_transport(a, b, o);
  EXPECT_NEAR(tn.transport_cost, glm::dot(v, v), 0.01 * glm::dot(v, v));
}

TEST(Imr, ExactBuresIsSymmetricTaylorIsNot) {
  const GaussianMixture a = random_mixture(150, 5), b = random_mixture(170, 6);
  ImrOptions o;
  o.sinkhorn.tolerance = 1e-10;
  o.sinkhorn.double_exp = true;
  o.cost.shape = ShapeCost::ExactBures;
  const double ab = mixture_transport(a, b, o).transport_cost, ba = mixture_transport(b, a, o).transport_cost;
  EXPECT_NEAR(ab, ba, 1e-7 * ab);
  o.cost.shape = ShapeCost::TaylorBures;
  const double tab = mixture_transport(a, b, o).transport_cost, tba = mixture_transport(b, a, o).transport_cost;
  EXPECT_GT(std::abs(tab - tba), 1e-6 * tab);
}

TEST(Imr, StorageModesAgree) {
  const GaussianMixture a = random_mixture(257, 7), b = random_mixture(199, 8);
  ImrOptions o;
  o.sinkhorn.tolerance = 1e-6;
  o.storage = CostStorage::StoredDouble;
  const double d = mixture_transport(a, b, o).transport_cost;
  o.storage = CostStorage::OnTheFly;
  EXPECT_DOUBLE_EQ(mixture_transport(a, b, o).transport_cost, d);
  o.storage = CostStorage::StoredFloat;
  EXPECT_NEAR(mixture_transport(a, b, o).transport_cost, d, 1e-6 * d);
}

// A transport whose matrices exceed the machine's memory (10^6 × 10^6 components: terabytes under every
// storage) is refused before anything that size is allocated, naming the sizes and the way out.
TEST(Imr, ATransportLargerThanMemoryIsRefusedFirst) {
  GaussianMixture a, b;
  for (GaussianMixture* g : {&a, &b}) {
    g->means.resize(1000000);
    g->covariances.resize(1000000);
    g->weights.assign(1000000, 1e-6);
  }
  ImrOptions o;
  for (const CostStorage storage : {CostStorage::StoredFloat, CostStorage::StoredDouble, CostStorage::OnTheFly})
    for (const SinkhornMethod method : {SinkhornMethod::LogDomain, SinkhornMethod::StabilizedKernel}) {
      o.storage = storage;
      o.sinkhorn.method = method;
      if (storage == CostStorage::OnTheFly && method == SinkhornMethod::LogDomain) continue;  // nothing n × m kept
      try {
        mixture_transport(a, b, o);
        ADD_FAILURE() << to_string(storage) << " " << to_string(method);
      } catch (const Error& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find("1000000 × 1000000 components"), std::string::npos) << what;
        EXPECT_NE(what.find("fewer --samples"), std::string::npos) << what;
      }
    }
}

TEST(Imr, MetricFromDistances) {
  EXPECT_DOUBLE_EQ(imr_from_distances({2.0}), std::log(2.0));
  EXPECT_DOUBLE_EQ(imr_from_distances({1.0, 2.0, 3.0}), std::log(14.0 / 6.0));
  EXPECT_THROW(imr_from_distances({}), Error);
  EXPECT_THROW(imr_from_distances({0.0}), Error);
  const GaussianMixture a = random_mixture(50, 1), b = random_mixture(60, 2), c = random_mixture(70, 3);
  ImrOptions o;
  o.debiased = true;
  const ImrResult r = compute_imr({a, b, c}, o);
  ASSERT_EQ(r.pairs.size(), 3u);
  EXPECT_EQ(r.pairs[2].a, 1u);
  EXPECT_EQ(r.pairs[2].b, 2u);
  std::vector<double> d;
  for (const auto& p : r.pairs) {
    d.push_back(p.distance);
    EXPECT_DOUBLE_EQ(p.distance * p.distance, p.transport.transport_cost);
    EXPECT_GT(*p.debiased, 0.0);
  }
  EXPECT_DOUBLE_EQ(r.imr, imr_from_distances(d));
  ASSERT_TRUE(r.imr_debiased.has_value());
  EXPECT_THROW(compute_imr({a}, o), Error);
}

}  // namespace
}  // namespace d2gs
