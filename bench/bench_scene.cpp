// Scene loading: metadata (poses, intrinsics, image sizes from headers) and decoding one view.
#include <benchmark/benchmark.h>

#include <string>

#include "d2gs/scene/scene.hpp"

namespace {

const std::string kFern = std::string(D2GS_SHARED_DATA_DIR) + "/nerf_llff_data/fern";
const std::string kRoom = std::string(D2GS_SHARED_DATA_DIR) + "/llff_nex_reprocessed/room";

void BM_LoadSceneMetadata(benchmark::State& state) {
  const std::string& root = state.range(0) == 0 ? kFern : kRoom;
  d2gs::SceneLoadOptions o;
  o.resolution = 8;
  for (auto _ : state) benchmark::DoNotOptimize(d2gs::load_scene(root, o).cameras.size());
}
BENCHMARK(BM_LoadSceneMetadata)->Arg(0)->Arg(1)->ArgName("fern0_room1")->Unit(benchmark::kMillisecond);

void BM_LoadImage(benchmark::State& state) {
  // fern -r 8 reads images_8 directly; room -r 8 decodes a 996×746 JPEG and area-resamples it.
  const std::string& root = state.range(0) == 0 ? kFern : kRoom;
  d2gs::SceneLoadOptions o;
  o.resolution = 8;
  const auto scene = d2gs::load_scene(root, o);
  for (auto _ : state) benchmark::DoNotOptimize(d2gs::load_image(scene, 1).pixels.data());
}
BENCHMARK(BM_LoadImage)->Arg(0)->Arg(1)->ArgName("fern0_room1")->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
