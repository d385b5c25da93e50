// Training-iteration cost on real data: fern, 3 views, 504×378, from the published pipeline's 3-view cloud
// (../shared/data/published_init/fern, 17 903 points: the start of issue 26's reference run; a file, so no
// stereo is built per benchmark), for each method. Reported per iteration (render, loss, backward, densification statistics, Adam).
// And DD-Drop's own parts (method.md §4): the kNN density refresh (t = 1 and every 500 iterations) and
// the per-iteration mask (depths, tertile layers, probabilities, Bernoulli draws), on N Gaussians drawn
// around fern's SfM points (a point picked at random, jittered by 0.3 % of the cloud's box diagonal:
// about the clustering a trained fern model of 38k Gaussians has).
#include <benchmark/benchmark.h>

#include <cmath>
#include <filesystem>

#include "d2gs/core/random.hpp"
#include "d2gs/scene/scene.hpp"
#include "d2gs/train/dropout.hpp"
#include "d2gs/train/methods/registry.hpp"
#include "d2gs/train/trainer.hpp"

namespace {

d2gs::Gaussians fern_like_model(std::size_t n) {
  d2gs::SceneLoadOptions o;
  o.resolution = 8;
  const d2gs::Scene scene = d2gs::load_scene(std::string(D2GS_SHARED_DATA_DIR) + "/nerf_llff_data/fern", o);
  const auto& pts = scene.sfm_points.positions;
  glm::vec3 lo(1e30f), hi(-1e30f);
  for (const auto& p : pts) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  const double sigma = 0.003 * glm::length(hi - lo);
  d2gs::Rng rng = d2gs::Rng::stream(7, "bench-dd-drop");
  d2gs::Gaussians g;
  g.resize(n, 0);
  for (std::size_t i = 0; i < n; ++i) {
    const auto& p = pts[rng.below(pts.size())];
    for (int d = 0; d < 3; ++d) g.means[i * 3 + d] = p[d] + static_cast<float>(sigma * rng.normal());
  }
  return g;
}

void BM_DensityRefresh(benchmark::State& state) {
  const d2gs::Gaussians g = fern_like_model(static_cast<std::size_t>(state.range(0)));
  for (auto _ : state) benchmark::DoNotOptimize(d2gs::density_scores(g).data());
}
BENCHMARK(BM_DensityRefresh)->Arg(10000)->Arg(40000)->Arg(100000)->Unit(benchmark::kMillisecond);

void BM_DdDropMask(benchmark::State& state) {
  const d2gs::Gaussians g = fern_like_model(static_cast<std::size_t>(state.range(0)));
  d2gs::SceneLoadOptions o;
  o.resolution = 8;
  const d2gs::Scene scene = d2gs::load_scene(std::string(D2GS_SHARED_DATA_DIR) + "/nerf_llff_data/fern", o);
  const std::vector<float> density = d2gs::density_scores(g);
  d2gs::DdDropOptions opt;
  opt.depth_mode = d2gs::DepthMode::ReleaseDot;
  d2gs::Rng rng = d2gs::Rng::stream(1, "bench-dd-mask");
  std::vector<float> multiplier;
  for (auto _ : state) {
    const auto depths = d2gs::gaussian_depths(g, scene.cameras[0], opt.depth_mode);
    const auto p = d2gs::dd_drop_probabilities(depths, density, opt, 5000);
    d2gs::bernoulli_mask(p, rng, multiplier);
    benchmark::DoNotOptimize(multiplier.data());
  }
}
BENCHMARK(BM_DdDropMask)->Arg(10000)->Arg(40000)->Arg(100000)->Unit(benchmark::kMillisecond);

void BM_TrainIteration(benchmark::State& state) {
  // The method by its place in the registry (train/methods/registry.cpp): 0 3dgs, 1 dropgaussian, 2 d2gs.
  const std::string method = d2gs::training_methods().at(static_cast<std::size_t>(state.range(0))).name;
  const auto dir = std::filesystem::temp_directory_path() / "d2gs-bench-train";
  std::filesystem::remove_all(dir);
  d2gs::TrainConfig c;
  c.source = std::string(D2GS_SHARED_DATA_DIR) + "/nerf_llff_data/fern";
  c.model_dir = dir.string();
  c.resolution = 8;
  c.n_views = 3;
  c.init = std::string(D2GS_SHARED_DATA_DIR) + "/published_init/fern/3_views_fused.ply";
  c.method = method;
  state.SetLabel(method);
  c.quiet = true;
  d2gs::Trainer trainer(c);
  for (int i = 0; i < 3; ++i) trainer.step();  // warm the workspaces
  for (auto _ : state) benchmark::DoNotOptimize(trainer.step());
  state.counters["gaussians"] = static_cast<double>(trainer.model().size());
  std::filesystem::remove_all(dir);
}
BENCHMARK(BM_TrainIteration)->Arg(0)->Arg(1)->Arg(2)->ArgName("method")->Unit(benchmark::kMillisecond)->Iterations(20);

}  // namespace

BENCHMARK_MAIN();
