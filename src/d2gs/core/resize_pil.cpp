#include "d2gs/core/resize_pil.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "d2gs/core/error.hpp"

namespace d2gs {

namespace {

constexpr int kPrecisionBits = 32 - 8 - 2;  // PIL's fixed point for 8-bit images

double bicubic(double x) {
  constexpr double a = -0.5;
  x = std::abs(x);
  if (x < 1.0) return ((a + 2.0) * x - (a + 3.0)) * x * x + 1.0;
  if (x < 2.0) return (((x - 5.0) * x + 8.0) * x - 4.0) * a;
  return 0.0;
}

// Per output sample: the first input sample, the count, and the fixed-point weights (PIL's
// precompute_coeffs followed by normalize_coeffs_8bpc).
struct Coefficients {
  int ksize = 0;
  std::vector<int> first, count;
  std::vector<std::int32_t> weights;  // out_size x ksize
};

Coefficients precompute(int in_size, int out_size) {
  constexpr double support_base = 2.0;  // bicubic
  const double scale = static_cast<double>(in_size) / out_size;
  const double filterscale = std::max(scale, 1.0);
  const double support = support_base * filterscale;
  Coefficients c;
  c.ksize = static_cast<int>(std::ceil(support)) * 2 + 1;
  c.first.resize(static_cast<std::size_t>(out_size));
  c.count.resize(static_cast<std::size_t>(out_size));
  c.weights.assign(static_cast<std::size_t>(out_size) * c.ksize, 0);
  std::vector<double> k(static_cast<std::size_t>(c.ksize));
  for (int xx = 0; xx < out_size; ++xx) {
    const double center = (xx + 0.5) * scale;
    const double ss = 1.0 / filterscale;
    const int xmin = std::max(0, static_cast<int>(center - support + 0.5));
    const int xmax = std::min(in_size, static_cast<int>(center + support + 0.5)) - xmin;
    double ww = 0.0;
    for (int x = 0; x < xmax; ++x) {
      k[static_cast<std::size_t>(x)] = bicubic((x + xmin - center + 0.5) * ss);
      ww += k[static_cast<std::size_t>(x)];
    }
    std::int32_t* w = c.weights.data() + static_cast<std::size_t>(xx) * c.ksize;
    for (int x = 0; x < xmax; ++x) {
      const double v = ww != 0.0 ? k[static_cast<std::size_t>(x)] / ww : k[static_cast<std::size_t>(x)];
      w[x] = static_cast<std::int32_t>(v < 0 ? -0.5 + v * (1 << kPrecisionBits) : 0.5 + v * (1 << kPrecisionBits));
    }
    c.first[static_cast<std::size_t>(xx)] = xmin;
    c.count[static_cast<std::size_t>(xx)] = std::max(0, xmax);
  }
  return c;
}

std::uint8_t clip8(std::int64_t v) {
  if (v <= 0) return 0;
  const std::int64_t shifted = v >> kPrecisionBits;
  return static_cast<std::uint8_t>(std::min<std::int64_t>(shifted, 255));
}

}  // namespace

Image resize_pil_bicubic(const Image& image, int width, int height) {
  if (width <= 0 || height <= 0) fail("resize_pil_bicubic: invalid target size {}x{}", width, height);
  if (image.width <= 0 || image.height <= 0) fail("resize_pil_bicubic: empty source image");
  const int C = image.channels, W = image.width, H = image.height;
  std::vector<std::uint8_t> src(image.pixels.size());
  for (std::size_t i = 0; i < src.size(); ++i)
    src[i] = static_cast<std::uint8_t>(std::lround(std::clamp(image.pixels[i], 0.0f, 1.0f) * 255.0f));

  const bool horizontal = width != W, vertical = height != H;
  const Coefficients ch = precompute(W, width), cv = precompute(H, height);
  // Rows of the source the vertical pass reads (PIL resamples only those horizontally).
  int row0 = 0, rows = H;
  if (vertical) {
    row0 = cv.first.front();
    rows = cv.first.back() + cv.count.back() - row0;
  }
  std::vector<std::uint8_t> mid;
  int mid_w = W;
  if (horizontal) {
    mid_w = width;
    mid.resize(static_cast<std::size_t>(rows) * width * C);
#pragma omp parallel for schedule(static)
    for (int y = 0; y < rows; ++y) {
      const std::uint8_t* in = src.data() + static_cast<std::size_t>(y + row0) * W * C;
      std::uint8_t* out = mid.data() + static_cast<std::size_t>(y) * width * C;
      for (int xx = 0; xx < width; ++xx) {
        const std::int32_t* k = ch.weights.data() + static_cast<std::size_t>(xx) * ch.ksize;
        const int xmin = ch.first[static_cast<std::size_t>(xx)], n = ch.count[static_cast<std::size_t>(xx)];
        for (int c = 0; c < C; ++c) {
          std::int64_t ss = std::int64_t{1} << (kPrecisionBits - 1);
          for (int x = 0; x < n; ++x) ss += static_cast<std::int64_t>(in[(x + xmin) * C + c]) * k[x];
          out[xx * C + c] = clip8(ss);
        }
      }
    }
  } else {
    mid.assign(src.begin() + static_cast<std::ptrdiff_t>(row0) * W * C,
               src.begin() + static_cast<std::ptrdiff_t>(row0 + rows) * W * C);
  }
  std::vector<std::uint8_t> dst;
  if (vertical) {
    dst.resize(static_cast<std::size_t>(height) * mid_w * C);
#pragma omp parallel for schedule(static)
    for (int yy = 0; yy < height; ++yy) {
      const std::int32_t* k = cv.weights.data() + static_cast<std::size_t>(yy) * cv.ksize;
      const int ymin = cv.first[static_cast<std::size_t>(yy)] - row0, n = cv.count[static_cast<std::size_t>(yy)];
      std::uint8_t* out = dst.data() + static_cast<std::size_t>(yy) * mid_w * C;
      for (int i = 0; i < mid_w * C; ++i) {
        std::int64_t ss = std::int64_t{1} << (kPrecisionBits - 1);
        for (int y = 0; y < n; ++y)
          ss += static_cast<std::int64_t>(mid[static_cast<std::size_t>(y + ymin) * mid_w * C + i]) * k[y];
        out[i] = clip8(ss);
      }
    }
  } else {
    dst = std::move(mid);
  }
  Image result(width, height, C);
  for (std::size_t i = 0; i < dst.size(); ++i) result.pixels[i] = static_cast<float>(dst[i]) / 255.0f;
  return result;
}

}  // namespace d2gs
