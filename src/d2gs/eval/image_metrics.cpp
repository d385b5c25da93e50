#include "d2gs/eval/image_metrics.hpp"

#include <cmath>
#include <limits>

#include "d2gs/eval/ssim.hpp"

namespace d2gs {

double psnr(const float* a, const float* b, std::size_t count) {
  double se = 0.0;
  for (std::size_t i = 0; i < count; ++i) {
    const double d = static_cast<double>(a[i]) - static_cast<double>(b[i]);
    se += d * d;
  }
  const double mse = se / static_cast<double>(count);
  if (mse == 0.0) return std::numeric_limits<double>::infinity();
  return -10.0 * std::log10(mse);
}

double ssim_metric(const float* a, const float* b, int width, int height, int channels) {
  return ssim(a, b, width, height, channels);
}

}  // namespace d2gs
