#pragma once
// LPIPS (method.md §6; Zhang et al. 2018, v0.1): a VGG16 or AlexNet trunk, per-pixel channel
// normalisation of five taps, squared differences weighted by 1×1 linear layers (no bias), spatial mean,
// sum over taps. Convolutions run as im2col + single-precision GEMM (OpenBLAS). The network is built
// from a weights file (safetensors, docs/formats.md): layer structure fixed by the trunk, channel counts
// read from the tensors, so width-reduced nets (tests) run through the same code.
#include <array>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "d2gs/core/image.hpp"
#include "d2gs/core/safetensors.hpp"

namespace d2gs {

// The range of the images fed to the network. LPIPS's own convention is [−1, 1] (`symmetric`: an image
// x in [0, 1] enters as 2x − 1); the sparse-view papers feed [0, 1] images unchanged (`unit`).
enum class LpipsInputRange { unit, symmetric };
const char* to_string(LpipsInputRange range);        // "unit" / "symmetric"
const char* range_label(LpipsInputRange range);      // "[0,1]" / "[-1,1]"
// Parses "unit" / "symmetric" (also "0,1" / "-1,1"); throws d2gs::Error naming `option` otherwise.
LpipsInputRange parse_lpips_input_range(std::string_view text, std::string_view option);

enum class LpipsTrunk { vgg16, alexnet };
const char* to_string(LpipsTrunk trunk);

struct LpipsDistance {
  double total = 0;
  std::array<double, 5> per_tap{};  // the spatial means of each tap (their sum is `total`)
};

// C (m×n, leading dimension ldc) = A (m×k, lda) · B (k×n, ldb), row-major single precision.
using LpipsGemm = void (*)(int m, int n, int k, const float* a, int lda, const float* b, int ldb, float* c, int ldc);
// OpenBLAS's sgemm (the default).
void lpips_gemm_openblas(int m, int n, int k, const float* a, int lda, const float* b, int ldb, float* c, int ldc);

class Lpips {
public:
  // Builds the network from named tensors; `source` names their file in error messages. Expects the
  // trunk's torchvision names (`features.N.weight` [out, in, k, k], `features.N.bias` [out]) and
  // `linK.weight` ([1, C, 1, 1] or [C]) for K = 0..4, nothing else; all values finite.
  Lpips(const TensorFile& weights, const std::filesystem::path& source);
  static Lpips load(const std::filesystem::path& path);

  LpipsTrunk trunk() const { return trunk_; }
  const std::array<int, 5>& tap_channels() const { return tap_channels_; }
  const std::filesystem::path& source() const { return source_; }
  // e.g. "vgg16 (taps 64, 128, 256, 512, 512)".
  std::string description() const;
  // The smallest width and height (each) the trunk takes.
  int min_size() const;

  // LPIPS between two RGB images in [0, 1] of the same size (H×W×3 interleaved, as d2gs::Image).
  // Throws d2gs::Error (naming `what`) on mismatched sizes, too small images or non-finite values.
  LpipsDistance distance(const Image& a, const Image& b, LpipsInputRange range, std::string_view what = "images") const;

  // Replaces the GEMM (benchmarks compare implementations); nullptr restores OpenBLAS.
  void set_gemm(LpipsGemm gemm) { gemm_ = gemm ? gemm : lpips_gemm_openblas; }
  // The size of the im2col buffer (floats; columns are built a band of output rows at a time). Tests
  // shrink it to exercise the banding; results do not depend on it beyond rounding.
  void set_im2col_floats(std::size_t floats) { im2col_floats_ = floats; }
  // true (default): bands of output rows are shared among the OpenMP threads, each running a
  // single-threaded GEMM (distance() sets OpenBLAS to one thread, process-wide; nothing else in d2gs uses
  // BLAS). false: bands in turn, each GEMM threaded by OpenBLAS (measured in docs/benchmarks.md).
  void set_parallel_bands(bool on) { parallel_bands_ = on; }

private:
  struct Conv {
    int in = 0, out = 0, kernel = 0, stride = 1, pad = 0;
    std::vector<float> weight;  // out × (in·k·k), row-major
    std::vector<float> bias;
  };
  struct Op {
    enum Kind { conv_relu, max_pool, tap } kind;
    int index = 0;             // conv: into convs_; tap: 0..4
    int kernel = 0, stride = 0;  // max_pool
  };
  struct Features {
    int channels = 0, height = 0, width = 0;
    std::vector<float> values;  // channels × height × width (planar)
  };

  std::vector<Features> run_trunk(const Image& image, LpipsInputRange range) const;
  Features conv_relu(const Features& in, const Conv& conv) const;

  LpipsTrunk trunk_ = LpipsTrunk::vgg16;
  std::filesystem::path source_;
  std::vector<Conv> convs_;
  std::vector<Op> ops_;
  std::array<std::vector<float>, 5> lin_;
  std::array<int, 5> tap_channels_{};
  LpipsGemm gemm_ = lpips_gemm_openblas;
  std::size_t im2col_floats_ = std::size_t{1} << 22;
  bool parallel_bands_ = true;
};

}  // namespace d2gs
