#pragma once
// The per-value arithmetic of the photometric losses (train/losses.cpp: l1_loss, dafe_loss) and of the
// render's clamp before them (the trainer), shared
// unchanged by the CPU and the CUDA backend's kernels (train/kernels/l1_kernels.hpp, dafe_kernels.hpp).
// C++17, no standard library: nvcc compiles it.
#include <math.h>

#include "d2gs/core/host_device.hpp"

namespace d2gs {

// The losses see the render clamped to [0, 1] (std::clamp's order of tests: NaN stays NaN), and no
// gradient reaches a value the clamp changed.
D2GS_HD float clamp_unit(float v) { return v < 0.0f ? 0.0f : 1.0f < v ? 1.0f : v; }
D2GS_HD bool clamp_blocks_gradient(float v) { return v < 0.0f || v > 1.0f; }

// |x|' with 0 at 0, as torch's sign.
D2GS_HD float loss_sign(float x) { return x > 0.0f ? 1.0f : x < 0.0f ? -1.0f : 0.0f; }

// DAFE (method.md §5) on value (pixel p, channel c): its term |a − b| of the masked sum where mask[p] is
// set (0 elsewhere), the denominator of the loss (the paper's: the masked pixels; the release's: all C·H·W
// values), the gradient's scale g = scale/denominator rounded to float once, and the value's gradient.
D2GS_HD float dafe_term(float a, float b) { return fabsf(a - b); }
D2GS_HD double dafe_denominator(double masked_pixels, double values, bool paper_form) {
  return paper_form ? masked_pixels : values;
}
D2GS_HD float dafe_gradient_scale(float scale, double denominator) { return static_cast<float>(scale / denominator); }
D2GS_HD float dafe_gradient(float g, float a, float b) { return g * loss_sign(a - b); }

}  // namespace d2gs
