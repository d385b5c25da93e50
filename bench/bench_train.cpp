// Training-iteration cost on real data: fern, 3 views, 504×378, the all-view SfM init (10 091 points),
// for each method. Reported per iteration (render, loss, backward, densification statistics, Adam).
#include <benchmark/benchmark.h>

#include <filesystem>

#include "d2gs/train/trainer.hpp"

namespace {

void BM_TrainIteration(benchmark::State& state) {
  const auto method = static_cast<d2gs::Method>(state.range(0));
  const auto dir = std::filesystem::temp_directory_path() / "d2gs-bench-train";
  std::filesystem::remove_all(dir);
  d2gs::TrainConfig c;
  c.source = std::string(D2GS_SHARED_DATA_DIR) + "/nerf_llff_data/fern";
  c.model_dir = dir.string();
  c.resolution = 8;
  c.n_views = 3;
  c.method = method;
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
