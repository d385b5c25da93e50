#include "d2gs/eval/lpips.hpp"

#include <algorithm>
#include <cmath>
#include <set>

#include <cblas.h>
#include <fmt/format.h>
#include <omp.h>

#include "d2gs/core/error.hpp"

namespace d2gs {
namespace {

// LPIPS's ScalingLayer: (x − shift) / scale per RGB channel, on images in [−1, 1].
constexpr std::array<float, 3> kShift = {-0.030f, -0.088f, -0.188f};
constexpr std::array<float, 3> kScale = {0.458f, 0.448f, 0.450f};
constexpr double kNormEps = 1e-10;

struct LayerSpec {
  int feature_index, kernel, stride, pad;
};

// torchvision's vgg16().features: 3×3 convolutions (padding 1) at these indices, each followed by an
// in-place ReLU; 2×2 max pools at 4, 9, 16, 23. LPIPS taps relu1_2, relu2_2, relu3_3, relu4_3, relu5_3.
constexpr std::array<LayerSpec, 13> kVgg16 = {{{0, 3, 1, 1}, {2, 3, 1, 1}, {5, 3, 1, 1}, {7, 3, 1, 1}, {10, 3, 1, 1},
                                               {12, 3, 1, 1}, {14, 3, 1, 1}, {17, 3, 1, 1}, {19, 3, 1, 1},
                                               {21, 3, 1, 1}, {24, 3, 1, 1}, {26, 3, 1, 1}, {28, 3, 1, 1}}};
// torchvision's alexnet().features: conv 11×11/4 pad 2, pool 3/2, conv 5×5 pad 2, pool 3/2, three 3×3 pad 1
// convs; LPIPS taps relu1..relu5.
constexpr std::array<LayerSpec, 5> kAlexnet = {{{0, 11, 4, 2}, {3, 5, 1, 2}, {6, 3, 1, 1}, {8, 3, 1, 1}, {10, 3, 1, 1}}};

std::string shape_str(const std::vector<std::int64_t>& s) { return fmt::format("[{}]", fmt::join(s, ", ")); }

int conv_out(int size, int kernel, int stride, int pad) {
  const int span = size + 2 * pad - kernel;
  return span < 0 ? 0 : span / stride + 1;
}
int pool_out(int size, int kernel, int stride) { return size < kernel ? 0 : (size - kernel) / stride + 1; }

}  // namespace

const char* to_string(LpipsInputRange range) { return range == LpipsInputRange::unit ? "unit" : "symmetric"; }
const char* range_label(LpipsInputRange range) { return range == LpipsInputRange::unit ? "[0,1]" : "[-1,1]"; }

LpipsInputRange parse_lpips_input_range(std::string_view text, std::string_view option) {
  if (text == "unit" || text == "0,1" || text == "[0,1]") return LpipsInputRange::unit;
  if (text == "symmetric" || text == "-1,1" || text == "[-1,1]") return LpipsInputRange::symmetric;
  fail("{}: unknown LPIPS input range '{}' (unit = [0,1] as the sparse-view papers, symmetric = [-1,1] as LPIPS)",
       option, text);
}

const char* to_string(LpipsTrunk trunk) { return trunk == LpipsTrunk::vgg16 ? "vgg16" : "alexnet"; }

void lpips_gemm_openblas(int m, int n, int k, const float* a, int lda, const float* b, int ldb, float* c, int ldc) {
  cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, m, n, k, 1.0f, a, lda, b, ldb, 0.0f, c, ldc);
}

Lpips::Lpips(const TensorFile& weights, const std::filesystem::path& source) : source_(source) {
  const auto& t = weights.tensors;
  const auto first = t.find("features.0.weight");
  if (first == t.end()) fail_file(source, "no tensor 'features.0.weight' (not an LPIPS weights file? see docs/formats.md)");
  if (first->second.shape.size() != 4) fail_file(source, "features.0.weight has shape {}, expected [out, 3, k, k]", shape_str(first->second.shape));
  const auto k0 = first->second.shape[3];
  if (k0 == 3) trunk_ = LpipsTrunk::vgg16;
  else if (k0 == 11) trunk_ = LpipsTrunk::alexnet;
  else fail_file(source, "features.0.weight has {}×{} kernels: neither VGG16 (3×3) nor AlexNet (11×11)", k0, k0);
  if (auto m = weights.metadata.find("net"); m != weights.metadata.end() && m->second != to_string(trunk_))
    fail_file(source, "metadata says net '{}' but the tensors are a {} trunk", m->second, to_string(trunk_));

  std::vector<LayerSpec> specs;
  if (trunk_ == LpipsTrunk::vgg16) specs.assign(kVgg16.begin(), kVgg16.end());
  else specs.assign(kAlexnet.begin(), kAlexnet.end());

  std::set<std::string> used;
  auto take = [&](const std::string& name) -> const Tensor& {
    const auto it = t.find(name);
    if (it == t.end()) fail_file(source, "missing tensor '{}' for the {} trunk", name, to_string(trunk_));
    for (std::size_t i = 0; i < it->second.values.size(); ++i)
      if (!std::isfinite(it->second.values[i])) fail_file(source, "tensor '{}' holds a non-finite value at index {}", name, i);
    used.insert(name);
    return it->second;
  };
  int channels = 3;
  for (const auto& spec : specs) {
    const std::string wname = fmt::format("features.{}.weight", spec.feature_index);
    const std::string bname = fmt::format("features.{}.bias", spec.feature_index);
    const Tensor& w = take(wname);
    const Tensor& b = take(bname);
    if (w.shape.size() != 4 || w.shape[0] < 1 || w.shape[1] != channels || w.shape[2] != spec.kernel || w.shape[3] != spec.kernel)
      fail_file(source, "{} has shape {}, expected [out, {}, {}, {}]", wname, shape_str(w.shape), channels, spec.kernel, spec.kernel);
    if (b.shape != std::vector<std::int64_t>{w.shape[0]})
      fail_file(source, "{} has shape {}, expected [{}]", bname, shape_str(b.shape), w.shape[0]);
    Conv c;
    c.in = channels;
    c.out = static_cast<int>(w.shape[0]);
    c.kernel = spec.kernel;
    c.stride = spec.stride;
    c.pad = spec.pad;
    c.weight = w.values;
    c.bias = b.values;
    convs_.push_back(std::move(c));
    channels = static_cast<int>(w.shape[0]);
  }
  auto conv = [&](int i) { ops_.push_back({Op::conv_relu, i, 0, 0}); };
  auto pool = [&](int k, int s) { ops_.push_back({Op::max_pool, 0, k, s}); };
  auto tap = [&](int i, int conv_index) {
    ops_.push_back({Op::tap, i, 0, 0});
    tap_channels_[static_cast<std::size_t>(i)] = convs_[static_cast<std::size_t>(conv_index)].out;
  };
  if (trunk_ == LpipsTrunk::vgg16) {
    conv(0), conv(1), tap(0, 1), pool(2, 2);
    conv(2), conv(3), tap(1, 3), pool(2, 2);
    conv(4), conv(5), conv(6), tap(2, 6), pool(2, 2);
    conv(7), conv(8), conv(9), tap(3, 9), pool(2, 2);
    conv(10), conv(11), conv(12), tap(4, 12);
  } else {
    conv(0), tap(0, 0), pool(3, 2);
    conv(1), tap(1, 1), pool(3, 2);
    conv(2), tap(2, 2);
    conv(3), tap(3, 3);
    conv(4), tap(4, 4);
  }
  for (int k = 0; k < 5; ++k) {
    const std::string name = fmt::format("lin{}.weight", k);
    const Tensor& w = take(name);
    const std::int64_t c = tap_channels_[static_cast<std::size_t>(k)];
    if (w.shape != std::vector<std::int64_t>{1, c, 1, 1} && w.shape != std::vector<std::int64_t>{c})
      fail_file(source, "{} has shape {}, expected [1, {}, 1, 1] (the channels of tap {})", name, shape_str(w.shape), c, k);
    lin_[static_cast<std::size_t>(k)] = w.values;
  }
  for (const auto& [name, tensor] : t)
    if (!used.count(name)) fail_file(source, "unexpected tensor '{}' for an LPIPS {} file", name, to_string(trunk_));
}

Lpips Lpips::load(const std::filesystem::path& path) { return Lpips(read_safetensors(path), path); }

std::string Lpips::description() const {
  return fmt::format("{} (taps {})", to_string(trunk_), fmt::join(tap_channels_, ", "));
}

int Lpips::min_size() const {
  for (int s = 1; s < 4096; ++s) {
    int h = s;
    for (const Op& op : ops_) {
      if (op.kind == Op::conv_relu) {
        const Conv& c = convs_[static_cast<std::size_t>(op.index)];
        h = conv_out(h, c.kernel, c.stride, c.pad);
      } else if (op.kind == Op::max_pool) {
        h = pool_out(h, op.kernel, op.stride);
      }
      if (h < 1) break;
    }
    if (h >= 1) return s;
  }
  return 4096;
}

Lpips::Features Lpips::conv_relu(const Features& in, const Conv& c) const {
  Features out;
  out.channels = c.out;
  out.height = conv_out(in.height, c.kernel, c.stride, c.pad);
  out.width = conv_out(in.width, c.kernel, c.stride, c.pad);
  const std::size_t plane = static_cast<std::size_t>(out.height) * static_cast<std::size_t>(out.width);
  out.values.resize(static_cast<std::size_t>(c.out) * plane);
  const int kk = c.kernel * c.kernel;
  const std::size_t K = static_cast<std::size_t>(c.in) * static_cast<std::size_t>(kk);
  const std::size_t W = static_cast<std::size_t>(out.width);
  // Bands of output rows: each builds its im2col columns and runs one GEMM. In the default mode the
  // bands are shared among the OpenMP threads (single-threaded GEMMs); otherwise the bands run in turn
  // and the GEMM library threads each one.
  const int threads = parallel_bands_ ? std::max(1, omp_get_max_threads()) : 1;
  std::size_t rows_budget = std::max<std::size_t>(1, im2col_floats_ / static_cast<std::size_t>(threads) / (K * W));
  if (threads > 1) rows_budget = std::min<std::size_t>(rows_budget, (static_cast<std::size_t>(out.height) + 2 * threads - 1) / (2 * threads));
  const int band = static_cast<int>(std::clamp<std::size_t>(rows_budget, 1, static_cast<std::size_t>(out.height)));
  const int bands = (out.height + band - 1) / band;

  const auto run_band = [&](int b, std::vector<float>& col, bool threaded_im2col) {
    const int r0 = b * band;
    const int rows = std::min(band, out.height - r0);
    const int n = rows * out.width;
    // col[(ci·k + ky)·k + kx][(r − r0)·W_out + x] = input at (ci, r·s − p + ky, x·s − p + kx), zero outside.
    const auto fill_row = [&](std::size_t row) {
      const int ci = static_cast<int>(row) / kk, ky = (static_cast<int>(row) % kk) / c.kernel, kx = static_cast<int>(row) % c.kernel;
      float* dst = col.data() + row * static_cast<std::size_t>(n);
      const float* src = in.values.data() + static_cast<std::size_t>(ci) * static_cast<std::size_t>(in.height) * static_cast<std::size_t>(in.width);
      for (int r = 0; r < rows; ++r) {
        const int y = (r0 + r) * c.stride - c.pad + ky;
        float* d = dst + static_cast<std::size_t>(r) * W;
        if (y < 0 || y >= in.height) {
          std::fill(d, d + out.width, 0.0f);
          continue;
        }
        const float* s = src + static_cast<std::size_t>(y) * static_cast<std::size_t>(in.width);
        for (int x = 0; x < out.width; ++x) {
          const int xi = x * c.stride - c.pad + kx;
          d[x] = (xi >= 0 && xi < in.width) ? s[xi] : 0.0f;
        }
      }
    };
    if (threaded_im2col) {
#pragma omp parallel for schedule(static)
      for (std::ptrdiff_t row = 0; row < static_cast<std::ptrdiff_t>(K); ++row) fill_row(static_cast<std::size_t>(row));
    } else {
      for (std::size_t row = 0; row < K; ++row) fill_row(row);
    }
    float* dst = out.values.data() + static_cast<std::size_t>(r0) * W;
    gemm_(c.out, n, static_cast<int>(K), c.weight.data(), static_cast<int>(K), col.data(), n, dst, static_cast<int>(plane));
    for (int o = 0; o < c.out; ++o) {
      float* p = dst + static_cast<std::size_t>(o) * plane;
      const float bias = c.bias[static_cast<std::size_t>(o)];
      for (int i = 0; i < n; ++i) p[i] = std::max(p[i] + bias, 0.0f);
    }
  };
  const std::size_t col_size = K * static_cast<std::size_t>(band) * W;
  if (parallel_bands_) {
#pragma omp parallel num_threads(std::min(threads, bands))
    {
      std::vector<float> col(col_size);
#pragma omp for schedule(dynamic, 1)
      for (int b = 0; b < bands; ++b) run_band(b, col, false);
    }
  } else {
    std::vector<float> col(col_size);
    for (int b = 0; b < bands; ++b) run_band(b, col, true);
  }
  return out;
}

std::vector<Lpips::Features> Lpips::run_trunk(const Image& image, LpipsInputRange range) const {
  Features x;
  x.channels = 3;
  x.height = image.height;
  x.width = image.width;
  const std::size_t plane = static_cast<std::size_t>(image.width) * static_cast<std::size_t>(image.height);
  x.values.resize(3 * plane);
  for (std::size_t i = 0; i < plane; ++i)
    for (std::size_t ch = 0; ch < 3; ++ch) {
      const float v = image.pixels[i * 3 + ch];
      const float in = range == LpipsInputRange::unit ? v : 2.0f * v - 1.0f;
      x.values[ch * plane + i] = (in - kShift[ch]) / kScale[ch];
    }
  // The taps keep their features (moved, not copied); `cur` is what the next layer reads.
  std::vector<Features> taps(5);
  const Features* cur = &x;
  for (const Op& op : ops_) {
    if (op.kind == Op::conv_relu) {
      x = conv_relu(*cur, convs_[static_cast<std::size_t>(op.index)]);
      cur = &x;
    } else if (op.kind == Op::tap) {
      taps[static_cast<std::size_t>(op.index)] = std::move(x);
      cur = &taps[static_cast<std::size_t>(op.index)];
    } else {
      const Features& in = *cur;
      Features y;
      y.channels = in.channels;
      y.height = pool_out(in.height, op.kernel, op.stride);
      y.width = pool_out(in.width, op.kernel, op.stride);
      y.values.resize(static_cast<std::size_t>(y.channels) * static_cast<std::size_t>(y.height) * static_cast<std::size_t>(y.width));
#pragma omp parallel for schedule(static)
      for (int ch = 0; ch < y.channels; ++ch)
        for (int r = 0; r < y.height; ++r)
          for (int q = 0; q < y.width; ++q) {
            float m = -std::numeric_limits<float>::infinity();
            for (int dy = 0; dy < op.kernel; ++dy)
              for (int dx = 0; dx < op.kernel; ++dx)
                m = std::max(m, in.values[(static_cast<std::size_t>(ch) * static_cast<std::size_t>(in.height) +
                                           static_cast<std::size_t>(r * op.stride + dy)) * static_cast<std::size_t>(in.width) +
                                          static_cast<std::size_t>(q * op.stride + dx)]);
            y.values[(static_cast<std::size_t>(ch) * static_cast<std::size_t>(y.height) + static_cast<std::size_t>(r)) *
                         static_cast<std::size_t>(y.width) + static_cast<std::size_t>(q)] = m;
          }
      x = std::move(y);
      cur = &x;
    }
  }
  return taps;
}

LpipsDistance Lpips::distance(const Image& a, const Image& b, LpipsInputRange range, std::string_view what) const {
  if (a.channels != 3 || b.channels != 3) fail("LPIPS ({}): expected RGB images, got {} and {} channels", what, a.channels, b.channels);
  if (a.width != b.width || a.height != b.height)
    fail("LPIPS ({}): sizes differ, {}x{} and {}x{}", what, a.width, a.height, b.width, b.height);
  const int need = min_size();
  if (a.width < need || a.height < need)
    fail("LPIPS ({}): a {}x{} image is too small for the {} trunk (at least {}x{})", what, a.width, a.height, to_string(trunk_), need, need);
  for (const Image* im : {&a, &b})
    for (std::size_t i = 0; i < im->pixels.size(); ++i)
      if (!std::isfinite(im->pixels[i]))
        fail("LPIPS ({}): the {} image has a non-finite value at pixel ({}, {})", what, im == &a ? "first" : "second",
             (i / 3) % static_cast<std::size_t>(im->width), (i / 3) / static_cast<std::size_t>(im->width));
  // One GEMM per OpenMP thread: OpenBLAS must not start threads of its own inside them.
  if (parallel_bands_ && gemm_ == lpips_gemm_openblas) openblas_set_num_threads(1);
  const auto fa = run_trunk(a, range);
  const auto fb = run_trunk(b, range);
  LpipsDistance d;
  for (std::size_t k = 0; k < 5; ++k) {
    const Features& f0 = fa[k];
    const Features& f1 = fb[k];
    const std::size_t plane = static_cast<std::size_t>(f0.height) * static_cast<std::size_t>(f0.width);
    std::vector<double> n0(plane, 0.0), n1(plane, 0.0), acc(plane, 0.0);
    for (int ch = 0; ch < f0.channels; ++ch) {
      const float* p0 = f0.values.data() + static_cast<std::size_t>(ch) * plane;
      const float* p1 = f1.values.data() + static_cast<std::size_t>(ch) * plane;
      for (std::size_t i = 0; i < plane; ++i) {
        n0[i] += static_cast<double>(p0[i]) * p0[i];
        n1[i] += static_cast<double>(p1[i]) * p1[i];
      }
    }
    for (std::size_t i = 0; i < plane; ++i) {
      n0[i] = 1.0 / (std::sqrt(n0[i]) + kNormEps);
      n1[i] = 1.0 / (std::sqrt(n1[i]) + kNormEps);
    }
    for (int ch = 0; ch < f0.channels; ++ch) {
      const float* p0 = f0.values.data() + static_cast<std::size_t>(ch) * plane;
      const float* p1 = f1.values.data() + static_cast<std::size_t>(ch) * plane;
      const double w = lin_[k][static_cast<std::size_t>(ch)];
      for (std::size_t i = 0; i < plane; ++i) {
        const double diff = p0[i] * n0[i] - p1[i] * n1[i];
        acc[i] += w * diff * diff;
      }
    }
    double sum = 0;
    for (double v : acc) sum += v;
    d.per_tap[k] = sum / static_cast<double>(plane);
    d.total += d.per_tap[k];
  }
  return d;
}

}  // namespace d2gs
