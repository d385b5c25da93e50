#pragma once
// The Rasterizer interface (render/rasterizer.hpp) over a StageRunner: the CUDA backend's kernels as a
// whole renderer, forward and backward. On the GPU (render::make_rasterizer, render/device_choice.hpp) it
// is what `d2gs render/eval --device cuda` use, and `d2gs train --device cuda` for its rasterization; over
// the emulated stages it runs the same host code and kernel bodies on the CPU, which the tests compare
// with the CPU rasterizer.
// Each forward() uploads the model and downloads the images and radii; each backward() uploads the image
// gradients and downloads the model gradients (a training step that keeps everything on the device is
// still to come, issue 27).
#include <memory>

#include "d2gs/render/kernels/stages.hpp"
#include "d2gs/render/rasterizer.hpp"

namespace d2gs::render::kernels {

// fused_multiply_add: whether compositing fuses its per-pixel multiply-adds (the GPU's natural choice;
// the CPU's tile loops fuse at x86-64-v3 and above, not at the SSE2 baseline).
std::unique_ptr<Rasterizer> make_kernel_rasterizer(std::unique_ptr<StageRunner> stages, bool fused_multiply_add);

}  // namespace d2gs::render::kernels
