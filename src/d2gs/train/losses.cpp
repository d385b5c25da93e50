#include "d2gs/train/losses.hpp"

#include <algorithm>
#include <cmath>

#include "d2gs/core/error.hpp"
#include "d2gs/core/percentile.hpp"
#include "d2gs/train/loss_math.hpp"

namespace d2gs {

double l1_loss(const float* a, const float* b, std::size_t count, float* grad, float scale) {
  if (count == 0) return 0.0;
  double sum = 0.0;
  const float g = scale / static_cast<float>(count);
  // In blocks: |a - b| (widened to double) and the gradient in a vectorisable pass, then the block's
  // values added to the sum one by one in element order (the rounding of the sequential loop).
  constexpr std::size_t kBlock = 256;
  double abs_diff[kBlock];
  for (std::size_t i0 = 0; i0 < count; i0 += kBlock) {
    const std::size_t nb = std::min(kBlock, count - i0);
    const float* ab = a + i0;
    const float* bb = b + i0;
    if (grad) {
      float* gb = grad + i0;
      for (std::size_t j = 0; j < nb; ++j) {
        const float d = ab[j] - bb[j];
        abs_diff[j] = static_cast<double>(std::abs(d));
        // loss_sign(d) as 1 - 0, 0 - 1 or 0 - 0 (+0, also for a NaN): the same values, without branches.
        const float sign = static_cast<float>(d > 0.0f) - static_cast<float>(d < 0.0f);
        gb[j] += g * sign;
      }
    } else {
      for (std::size_t j = 0; j < nb; ++j) abs_diff[j] = static_cast<double>(std::abs(ab[j] - bb[j]));
    }
    std::size_t j = 0;
    for (; j + 4 <= nb; j += 4) {
      sum += abs_diff[j];
      sum += abs_diff[j + 1];
      sum += abs_diff[j + 2];
      sum += abs_diff[j + 3];
    }
    for (; j < nb; ++j) sum += abs_diff[j];
  }
  return sum / static_cast<double>(count);
}

std::vector<std::uint8_t> dafe_mask(const std::vector<float>& prior, PriorKind kind, DafeMaskRule rule, double tau,
                                    const std::vector<std::uint8_t>* valid) {
  const std::size_t n = prior.size();
  if (valid && valid->size() != n) fail("DAFE: validity mask has {} pixels, prior {}", valid->size(), n);
  const auto ok = [&](std::size_t i) { return (!valid || (*valid)[i]) && std::isfinite(prior[i]); };
  std::vector<float> values;
  values.reserve(n);
  for (std::size_t i = 0; i < n; ++i)
    if (ok(i)) values.push_back(prior[i]);
  std::vector<std::uint8_t> mask(n, 0);
  if (values.empty()) return mask;
  if (rule == DafeMaskRule::Percentile) {
    if (!(tau >= 0.0 && tau <= 100.0)) fail("DAFE: mask percentage {} outside [0, 100]", tau);
    if (kind == PriorKind::Depth) {
      const double t = percentile(values, 100.0 - tau);
      for (std::size_t i = 0; i < n; ++i) mask[i] = ok(i) && prior[i] >= t;
    } else {
      const double t = percentile(values, tau);
      for (std::size_t i = 0; i < n; ++i) mask[i] = ok(i) && prior[i] <= t;
    }
  } else {
    if (kind != PriorKind::Depth)
      fail("DAFE: the threshold rule needs a depth prior (disparity has an unknown scale and shift)");
    if (!(tau >= 0.0 && tau <= 1.0)) fail("DAFE: threshold fraction {} outside [0, 1]", tau);
    const float dmax = *std::max_element(values.begin(), values.end());
    for (std::size_t i = 0; i < n; ++i) mask[i] = ok(i) && prior[i] > tau * dmax;
  }
  return mask;
}

double dafe_loss(const float* a, const float* b, int width, int height, int channels,
                 const std::vector<std::uint8_t>& mask, DafeLossForm form, float* grad, float scale) {
  const std::size_t pixels = static_cast<std::size_t>(width) * height;
  if (mask.size() != pixels) fail("DAFE: mask has {} pixels, image {}x{}", mask.size(), width, height);
  std::size_t masked = 0;
  for (auto m : mask) masked += m != 0;
  double sum = 0.0;
  for (std::size_t p = 0; p < pixels; ++p) {
    if (!mask[p]) continue;
    for (int c = 0; c < channels; ++c) sum += dafe_term(a[p * channels + c], b[p * channels + c]);
  }
  const double denom = dafe_denominator(static_cast<double>(masked), static_cast<double>(pixels) * channels,
                                        form == DafeLossForm::Paper);
  if (denom == 0.0) return 0.0;
  if (grad) {
    const float g = dafe_gradient_scale(scale, denom);
    for (std::size_t p = 0; p < pixels; ++p) {
      if (!mask[p]) continue;
      for (int c = 0; c < channels; ++c)
        grad[p * channels + c] += dafe_gradient(g, a[p * channels + c], b[p * channels + c]);
    }
  }
  return sum / denom;
}

double disparity_l1_loss(const float* depth_sum, const float* alpha, const float* target_depth, std::size_t count,
                         double alpha_min, float* grad_depth, float* grad_alpha, float scale) {
  // The normaliser: the pixels with a target and their mean target disparity.
  std::size_t targets = 0;
  double disparity_sum = 0.0;
  for (std::size_t i = 0; i < count; ++i)
    if (target_depth[i] > 0.0f) {
      ++targets;
      disparity_sum += 1.0 / static_cast<double>(target_depth[i]);
    }
  if (targets == 0 || !(disparity_sum > 0.0)) return 0.0;
  const double norm = 1.0 / disparity_sum;  // = 1 / (targets · mean disparity)
  double loss = 0.0;
  for (std::size_t i = 0; i < count; ++i) {
    const double z = target_depth[i], d = depth_sum[i], a = alpha[i];
    if (!(z > 0.0) || !(d > 0.0) || !(a >= alpha_min)) continue;
    const double diff = a / d - 1.0 / z;
    loss += std::abs(diff);
    const double sign = diff > 0.0 ? 1.0 : diff < 0.0 ? -1.0 : 0.0;
    if (grad_depth) grad_depth[i] += static_cast<float>(scale * norm * sign * (-a / (d * d)));
    if (grad_alpha) grad_alpha[i] += static_cast<float>(scale * norm * sign / d);
  }
  return loss * norm;
}

}  // namespace d2gs
