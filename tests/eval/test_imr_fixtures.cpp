// Agreement with an independent implementation: tests/eval/fixtures/ were written by
// tools/make_imr_fixtures.py (NumPy cost matrix + POT's ot.sinkhorn2(..., method='sinkhorn_log')).
// Here the mixture, the cost and the transport are recomputed from the stored model parameters.
#include <cstdio>
#include <fstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "d2gs/core/npy.hpp"
#include "d2gs/eval/imr.hpp"
#include "test_paths.hpp"

namespace d2gs {
namespace {

std::filesystem::path fixtures() { return test::source_dir() / "tests/eval/fixtures"; }

nlohmann::json load_fixtures() {
  std::ifstream in(fixtures() / "imr_fixtures.json");
  EXPECT_TRUE(in.good()) << "missing " << (fixtures() / "imr_fixtures.json");
  return nlohmann::json::parse(in);
}

std::vector<float> read_floats(const std::string& name) {
  const NpyArray a = read_npy(fixtures() / name);
  return std::vector<float>(a.values.begin(), a.values.end());
}

Gaussians load_model(const nlohmann::json& files) {
  Gaussians g;
  g.means = read_floats(files["means"]);
  g.log_scales = read_floats(files["log_scales"]);
  g.quats = read_floats(files["quats"]);
  g.opacity_logits = read_floats(files["opacity_logits"]);
  g.sh_dc.assign(g.opacity_logits.size() * 3, 0.0f);
  g.validate();
  return g;
}

GaussianMixture load_mixture(const nlohmann::json& files) {
  const Gaussians g = load_model(files);
  std::vector<std::size_t> all(g.size());
  for (std::size_t i = 0; i < all.size(); ++i) all[i] = i;
  return mixture_from_model(g, all, /*sanitize=*/true);
}

TEST(ImrFixtures, CostAndTransportMatchNumpyAndPot) {
  const nlohmann::json fx = load_fixtures();
  ASSERT_GE(fx["cases"].size(), 5u);
  for (const auto& c : fx["cases"]) {
    SCOPED_TRACE(c["name"].get<std::string>());
    const GaussianMixture a = load_mixture(c["a"]), b = load_mixture(c["b"]);
    ImrOptions o;
    o.cost.shape = c["shape"] == "exact" ? ShapeCost::ExactBures : ShapeCost::TaylorBures;
    o.cost.clamp_shape = c["clamp"];
    o.cost.normalize = c["normalize"];
    o.sinkhorn.epsilon = c["epsilon"];
    const MixtureCost cost(a, b, o.cost);
    const double scale = c["scale"];
    EXPECT_NEAR(cost.scale(), scale, 1e-12 * scale);
    EXPECT_NEAR(cost.max_position_term(), c["max_position_term"].get<double>(), 1e-12 * cost.max_position_term());
    for (const auto& e : c["entries"]) {
      const double expected = e[2];
      EXPECT_NEAR(cost.entry(e[0], e[1]), expected, 1e-9 * (1.0 + expected)) << e;
    }
    const double pot = c["transport_cost"];
    // Release defaults (tolerance 1e-4 on the log-potentials), float-stored cost.
    const TransportResult t = mixture_transport(a, b, o);
    EXPECT_TRUE(t.converged);
    EXPECT_NEAR(t.transport_cost, pot, 1e-4 * pot);
    // The stabilised-kernel solver, release defaults otherwise.
    ImrOptions ok = o;
    ok.sinkhorn.method = SinkhornMethod::StabilizedKernel;
    const TransportResult k = mixture_transport(a, b, ok);
    EXPECT_TRUE(k.converged);
    EXPECT_NEAR(k.transport_cost, pot, 1e-4 * pot);
    EXPECT_NEAR(k.transport_cost, t.transport_cost, 2e-5 * pot);
    // Tight tolerance, cost stored in double; exp in double on the smaller cases.
    o.sinkhorn.max_iterations = 200000;
    o.storage = CostStorage::StoredDouble;
    o.sinkhorn.double_exp = a.size() * b.size() <= 500 * 500;
    o.sinkhorn.tolerance = o.sinkhorn.double_exp ? 1e-10 : 1e-6;
    const TransportResult tight = mixture_transport(a, b, o);
    EXPECT_NEAR(tight.transport_cost, pot, (o.sinkhorn.double_exp ? 1e-8 : 1e-6) * pot);
    // The kernel solver to a tight tolerance: no float-exp floor on its changes (the kernel is fixed between
    // absorptions), so 1e-9 is reachable with the float kernel.
    ok.sinkhorn.max_iterations = 200000;
    ok.sinkhorn.tolerance = 1e-9;
    const TransportResult ktight = mixture_transport(a, b, ok);
    EXPECT_TRUE(ktight.converged);
    EXPECT_NEAR(ktight.transport_cost, pot, 1e-6 * pot);
    std::printf("[ POT      ] %-20s kernel solver: default rel %.2e (%d its), tol 1e-9 rel %.2e (%d its, marginal err "
                "%.1e)\n",
                c["name"].get<std::string>().c_str(), std::abs(k.transport_cost - pot) / pot, k.iterations,
                std::abs(ktight.transport_cost - pot) / pot, ktight.iterations, ktight.marginal_error);
    std::printf("[ POT      ] %-20s %4zux%-4zu eps %-5g POT S = %.10g | d2gs default: rel %.2e (%d its, %.3f s) | "
                "tight: rel %.2e (%d its, marginal err %.1e)\n",
                c["name"].get<std::string>().c_str(), a.size(), b.size(), o.sinkhorn.epsilon, pot,
                std::abs(t.transport_cost - pot) / pot, t.iterations, t.seconds,
                std::abs(tight.transport_cost - pot) / pot, tight.iterations, tight.marginal_error);
  }
}

TEST(ImrFixtures, DepthStrataMatchNumpy) {
  const nlohmann::json fx = load_fixtures();
  const auto& s = fx["depth_strata"];
  const Gaussians g = load_model(s["model"]);
  Camera cam;
  const std::vector<double> r = s["R_world_to_cam_row_major"];
  for (int row = 0; row < 3; ++row)
    for (int col = 0; col < 3; ++col) cam.R_world_to_cam[col][row] = r[static_cast<std::size_t>(row * 3 + col)];
  for (const auto& [samples, expected] : s["selections"].items()) {
    const auto picked = depth_strata_indices(imr_depths(g, cam), std::stoul(samples));
    EXPECT_EQ(picked, expected.get<std::vector<std::size_t>>()) << "samples " << samples;
  }
}

}  // namespace
}  // namespace d2gs
