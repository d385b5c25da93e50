// LPIPS benchmark (results in docs/benchmarks.md, "LPIPS").
//   bench_lpips --benchmark_repetitions=3
// One pair of real 504×378 images (fern at -r 8, test views 0 and 8) through full-width trunks with
// random weights (the time does not depend on the values). d2gs's network (im2col + OpenBLAS sgemm) in
// its two threading modes, and the same VGG16 built as an OpenCV dnn network as the
// alternative that was measured; the dnn variant also reports its relative difference to d2gs.
#include <cblas.h>
#include <omp.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>

#include <benchmark/benchmark.h>
#include <fmt/format.h>
#include <opencv2/core.hpp>
#include <opencv2/dnn.hpp>

#include "d2gs/eval/lpips.hpp"
#include "d2gs/scene/scene.hpp"

namespace {

struct ConvShape {
  int index, in, out, kernel;
};
const std::vector<ConvShape> kVgg16 = {{0, 3, 64, 3},     {2, 64, 64, 3},    {5, 64, 128, 3},   {7, 128, 128, 3},
                                       {10, 128, 256, 3}, {12, 256, 256, 3}, {14, 256, 256, 3}, {17, 256, 512, 3},
                                       {19, 512, 512, 3}, {21, 512, 512, 3}, {24, 512, 512, 3}, {26, 512, 512, 3},
                                       {28, 512, 512, 3}};
const std::vector<ConvShape> kAlexnet = {{0, 3, 64, 11}, {3, 64, 192, 5}, {6, 192, 384, 3}, {8, 384, 256, 3}, {10, 256, 256, 3}};

d2gs::TensorFile random_weights(const std::vector<ConvShape>& convs, const std::vector<int>& taps) {
  std::mt19937_64 rng(7);
  std::normal_distribution<float> n01;
  std::uniform_real_distribution<float> u01(0.0f, 0.1f);
  d2gs::TensorFile f;
  for (const auto& c : convs) {
    d2gs::Tensor w{{c.out, c.in, c.kernel, c.kernel}, std::vector<float>(static_cast<std::size_t>(c.out * c.in * c.kernel * c.kernel))};
    const float sd = std::sqrt(2.0f / static_cast<float>(c.in * c.kernel * c.kernel));
    for (auto& v : w.values) v = sd * n01(rng);
    d2gs::Tensor b{{c.out}, std::vector<float>(static_cast<std::size_t>(c.out))};
    for (auto& v : b.values) v = 0.05f * n01(rng);
    f.tensors[fmt::format("features.{}.weight", c.index)] = std::move(w);
    f.tensors[fmt::format("features.{}.bias", c.index)] = std::move(b);
  }
  for (std::size_t k = 0; k < taps.size(); ++k) {
    d2gs::Tensor l{{1, taps[k], 1, 1}, std::vector<float>(static_cast<std::size_t>(taps[k]))};
    for (auto& v : l.values) v = u01(rng);
    f.tensors[fmt::format("lin{}.weight", k)] = std::move(l);
  }
  return f;
}

const std::pair<d2gs::Image, d2gs::Image>& fern_pair() {
  static const auto pair = [] {
    d2gs::SceneLoadOptions o;
    o.resolution = 8;
    const auto scene = d2gs::load_scene(std::filesystem::path(D2GS_SHARED_DATA_DIR) / "nerf_llff_data/fern", o);
    return std::make_pair(d2gs::load_image(scene, 0), d2gs::load_image(scene, 8));
  }();
  return pair;
}

// Args: net (0 vgg16, 1 alexnet), mode (0: bands shared among OpenMP threads, single-threaded GEMMs, the
// default; 1: bands in turn, GEMMs threaded by OpenBLAS), threads (OpenMP threads in mode 0, OpenBLAS
// threads in mode 1).
void BM_LpipsOpenBlas(benchmark::State& state) {
  const bool vgg = state.range(0) == 0;
  const bool bands = state.range(1) == 0;
  const int threads = static_cast<int>(state.range(2));
  d2gs::Lpips net(vgg ? random_weights(kVgg16, {64, 128, 256, 512, 512}) : random_weights(kAlexnet, {64, 192, 384, 256, 256}),
                  "random");
  net.set_parallel_bands(bands);
  const auto& [a, b] = fern_pair();
  const int omp_before = omp_get_max_threads();
  if (bands) omp_set_num_threads(threads);
  else openblas_set_num_threads(threads);
  for (auto _ : state) benchmark::DoNotOptimize(net.distance(a, b, d2gs::LpipsInputRange::unit).total);
  omp_set_num_threads(omp_before);
  state.SetLabel(fmt::format("{} {}x{}, {}, {} thread(s) ({})", vgg ? "vgg16" : "alexnet", a.width, a.height,
                             bands ? "OpenMP bands" : "OpenBLAS-threaded GEMM", threads, openblas_get_config()));
}
BENCHMARK(BM_LpipsOpenBlas)
    ->Args({0, 0, 2})
    ->Args({0, 0, 1})
    ->Args({0, 1, 2})
    ->Args({1, 0, 2})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MeasureProcessCPUTime();

// The same VGG16 LPIPS with the trunk as an OpenCV dnn network (the measured alternative).
cv::Mat prep(const d2gs::Image& im) {
  const int sz[] = {1, 3, im.height, im.width};
  cv::Mat blob(4, sz, CV_32F);
  const float shift[] = {-0.030f, -0.088f, -0.188f}, scale[] = {0.458f, 0.448f, 0.450f};
  const std::size_t plane = static_cast<std::size_t>(im.width) * static_cast<std::size_t>(im.height);
  auto* p = blob.ptr<float>();
  for (std::size_t i = 0; i < plane; ++i)
    for (std::size_t c = 0; c < 3; ++c) p[c * plane + i] = (im.pixels[i * 3 + c] - shift[c]) / scale[c];
  return blob;
}

double dnn_lpips(cv::dnn::Net& net, const std::vector<std::string>& taps, const d2gs::TensorFile& w, const d2gs::Image& a,
                 const d2gs::Image& b) {
  std::vector<cv::Mat> fa, fb;
  net.setInput(prep(a));
  net.forward(fa, taps);
  net.setInput(prep(b));
  net.forward(fb, taps);
  double total = 0;
  for (std::size_t k = 0; k < taps.size(); ++k) {
    const int c = fa[k].size[1];
    const std::size_t plane = static_cast<std::size_t>(fa[k].size[2]) * static_cast<std::size_t>(fa[k].size[3]);
    const float* p0 = fa[k].ptr<float>();
    const float* p1 = fb[k].ptr<float>();
    const auto& lin = w.tensors.at(fmt::format("lin{}", k) + ".weight").values;
    double sum = 0;
    for (std::size_t i = 0; i < plane; ++i) {
      double n0 = 0, n1 = 0, d = 0;
      for (int ch = 0; ch < c; ++ch) {
        n0 += double(p0[ch * plane + i]) * p0[ch * plane + i];
        n1 += double(p1[ch * plane + i]) * p1[ch * plane + i];
      }
      n0 = 1.0 / (std::sqrt(n0) + 1e-10), n1 = 1.0 / (std::sqrt(n1) + 1e-10);
      for (int ch = 0; ch < c; ++ch) {
        const double diff = p0[ch * plane + i] * n0 - p1[ch * plane + i] * n1;
        d += lin[static_cast<std::size_t>(ch)] * diff * diff;
      }
      sum += d;
    }
    total += sum / static_cast<double>(plane);
    if (std::getenv("D2GS_BENCH_VERBOSE")) std::fprintf(stderr, "dnn tap %zu: %.8g\n", k, sum / static_cast<double>(plane));
  }
  return total;
}

void BM_LpipsOpenCvDnn(benchmark::State& state) {
  const int threads = static_cast<int>(state.range(0));
  const auto w = random_weights(kVgg16, {64, 128, 256, 512, 512});
  cv::dnn::Net net;
  net.setInputsNames({"data"});
  std::vector<std::string> taps;
  const std::vector<int> tap_after = {2, 7, 14, 21, 28};  // relu of features.2, 7, 14, 21, 28
  const std::vector<int> pool_after = {2, 7, 14, 21};
  for (const auto& c : kVgg16) {
    cv::dnn::LayerParams lp;
    lp.set("kernel_size", 3);
    lp.set("pad", 1);
    lp.set("stride", 1);
    lp.set("num_output", c.out);
    lp.set("bias_term", true);
    const auto& wt = w.tensors.at(fmt::format("features.{}.weight", c.index));
    const int sz[] = {c.out, c.in, 3, 3};
    lp.blobs.push_back(cv::Mat(4, sz, CV_32F, const_cast<float*>(wt.values.data())).clone());
    const auto& bt = w.tensors.at(fmt::format("features.{}.bias", c.index));
    lp.blobs.push_back(cv::Mat(1, c.out, CV_32F, const_cast<float*>(bt.values.data())).clone());
    net.addLayerToPrev(fmt::format("conv{}", c.index), "Convolution", lp);
    cv::dnn::LayerParams relu;
    const std::string rname = fmt::format("relu{}", c.index);
    net.addLayerToPrev(rname, "ReLU", relu);
    if (std::find(tap_after.begin(), tap_after.end(), c.index) != tap_after.end()) taps.push_back(rname);
    if (std::find(pool_after.begin(), pool_after.end(), c.index) != pool_after.end()) {
      cv::dnn::LayerParams pool;
      pool.set("pool", "max");
      pool.set("kernel_size", 2);
      pool.set("stride", 2);
      pool.set("ceil_mode", false);  // torch floors; Caffe-style dnn pooling would ceil (189 rows -> 95)
      net.addLayerToPrev(fmt::format("pool{}", c.index), "Pooling", pool);
    }
  }
  net.setPreferableBackend(cv::dnn::DNN_BACKEND_OPENCV);
  net.setPreferableTarget(cv::dnn::DNN_TARGET_CPU);
  const auto& [a, b] = fern_pair();
  const int before = cv::getNumThreads();
  cv::setNumThreads(threads);
  double value = 0;
  for (auto _ : state) benchmark::DoNotOptimize(value = dnn_lpips(net, taps, w, a, b));
  cv::setNumThreads(before);
  const auto ours_d = d2gs::Lpips(w, "random").distance(a, b, d2gs::LpipsInputRange::unit);
  const double ours = ours_d.total;
  if (std::getenv("D2GS_BENCH_VERBOSE"))
    for (double t : ours_d.per_tap) std::fprintf(stderr, "d2gs tap: %.8g\n", t);
  state.counters["rel_diff_to_d2gs"] = std::abs(value - ours) / ours;
  state.SetLabel(fmt::format("vgg16 {}x{}, OpenCV {} dnn, {} thread(s)", a.width, a.height, CV_VERSION, threads));
}
BENCHMARK(BM_LpipsOpenCvDnn)->Arg(2)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime()->MeasureProcessCPUTime();

}  // namespace
BENCHMARK_MAIN();
