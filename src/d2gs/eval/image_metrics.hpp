#pragma once
// Image metrics of method.md §6 on float images in [0, 1] (interleaved H×W×C).
#include <cstddef>

namespace d2gs {

// −10·log10(MSE) over all C·H·W values (infinite for identical images).
double psnr(const float* a, const float* b, std::size_t count);
// Mean SSIM (11×11 Gaussian window, σ 1.5, zero padding, C1 = 0.01², C2 = 0.03²); ssim.hpp.
double ssim_metric(const float* a, const float* b, int width, int height, int channels);

}  // namespace d2gs
