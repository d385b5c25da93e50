// IMR / Sinkhorn benchmark (results in docs/benchmarks.md, "IMR / Sinkhorn").
//   bench_imr --benchmark_filter=10000 --benchmark_repetitions=3
// One pair of random 10 000-component mixtures in a scene-like frame, ε = 0.1 on the mean-normalised release
// cost, tolerance 1e-4: time of cost preparation + solve, for the stored (float, double) and on-the-fly
// cost; the default (plain) solver and the accelerated one (d2gs imr --accelerated: Anderson, ε ÷4); the
// log-domain iterations and the stabilised kernel ones (d2gs imr --solver kernel).
// Trained pairs (the figures that matter): d2gs imr RUN_A RUN_B --samples N --accelerated --solver kernel.
// With D2GS_IMR_BENCH_DIR set, the two models are read from the .npy files that
// tools/bench_pot_sinkhorn.py writes there (a_means.npy, ...), so POT and d2gs solve the same pair.
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <random>
#include <string>

#include <benchmark/benchmark.h>

#include "d2gs/core/npy.hpp"
#include "d2gs/eval/imr.hpp"

namespace {

d2gs::Gaussians random_model(std::size_t n, unsigned seed) {
  d2gs::Gaussians g;
  g.resize(n, 0);
  std::mt19937_64 rng(seed);
  std::normal_distribution<float> n01;
  for (std::size_t i = 0; i < n; ++i) {
    g.means[3 * i] = 2.0f * n01(rng), g.means[3 * i + 1] = 1.5f * n01(rng), g.means[3 * i + 2] = 4.0f + 2.0f * n01(rng);
    for (int k = 0; k < 3; ++k) g.log_scales[3 * i + k] = std::log(0.03f) + 0.6f * n01(rng);
    for (int k = 0; k < 4; ++k) g.quats[4 * i + k] = n01(rng);
    g.opacity_logits[i] = 2.0f * n01(rng);
  }
  return g;
}

d2gs::Gaussians load_model(const std::filesystem::path& dir, const std::string& prefix) {
  const auto read = [&](const char* name) {
    const d2gs::NpyArray a = d2gs::read_npy(dir / (prefix + "_" + name + ".npy"));
    return std::vector<float>(a.values.begin(), a.values.end());
  };
  d2gs::Gaussians g;
  g.means = read("means");
  g.log_scales = read("log_scales");
  g.quats = read("quats");
  g.opacity_logits = read("opacity_logits");
  g.sh_dc.assign(g.opacity_logits.size() * 3, 0.0f);
  return g;
}

d2gs::GaussianMixture mixture(std::size_t n, unsigned seed, const char* prefix) {
  const char* dir = std::getenv("D2GS_IMR_BENCH_DIR");
  const d2gs::Gaussians g = dir ? load_model(dir, prefix) : random_model(n, seed);
  std::vector<std::size_t> first(std::min(n, g.size()));
  for (std::size_t i = 0; i < first.size(); ++i) first[i] = i;
  return d2gs::mixture_from_model(g, first, true);
}

void BM_ImrPair(benchmark::State& state) {
  const auto n = static_cast<std::size_t>(state.range(0));
  const auto storage = static_cast<d2gs::CostStorage>(state.range(1));
  const bool scaling = state.range(2) != 0;
  const bool plain = state.range(3) == 0;
  const auto method = state.range(4) != 0 ? d2gs::SinkhornMethod::StabilizedKernel : d2gs::SinkhornMethod::LogDomain;
  const d2gs::GaussianMixture a = mixture(n, 1, "a"), b = mixture(n, 2, "b");
  d2gs::ImrOptions options;  // the defaults of d2gs imr
  options.storage = storage;
  options.sinkhorn.epsilon_scaling = scaling;
  if (!plain) d2gs::use_accelerated_solver(options.sinkhorn);  // d2gs imr --accelerated
  options.sinkhorn.method = method;
  d2gs::TransportResult t;
  for (auto _ : state) {
    t = d2gs::mixture_transport(a, b, options);
  }
  state.counters["iterations"] = t.iterations;
  state.counters["marginal_err"] = t.marginal_error;
  state.counters["converged"] = t.converged;
  std::fprintf(stderr, "S = %.10g (scale %.10g, normalised %.10g)\n", t.transport_cost, t.scale, t.normalized_cost);
  state.SetLabel(std::string(d2gs::to_string(storage)) + (scaling ? ", eps-scaling" : ", no eps-scaling") +
                 (plain ? ", plain iterations" : ", Anderson") + ", " + d2gs::to_string(method));
}

// (n, storage, ε-scaling, accelerated, kernel): every storage with the accelerated solver, the stored float cost
// without ε-scaling, and the default plain solver with and without ε-scaling, each with log-domain and with
// stabilised-kernel iterations.
void args(benchmark::internal::Benchmark* b) {
  for (const int n : {2000, 10000})
    for (const int kernel : {0, 1}) {
      for (const auto s :
           {d2gs::CostStorage::StoredFloat, d2gs::CostStorage::StoredDouble, d2gs::CostStorage::OnTheFly})
        b->Args({n, static_cast<int>(s), 1, 1, kernel});
      const int stored = static_cast<int>(d2gs::CostStorage::StoredFloat);
      b->Args({n, stored, 0, 1, kernel});
      b->Args({n, stored, 1, 0, kernel});
      b->Args({n, stored, 0, 0, kernel});
    }
}

BENCHMARK(BM_ImrPair)->Apply(args)->Unit(benchmark::kSecond)->Iterations(1)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
