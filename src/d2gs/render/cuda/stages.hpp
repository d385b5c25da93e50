#pragma once
// The CUDA backend's per-Gaussian stages and binning on the GPU: the kernels of render/kernels/ launched
// through kernel_shell (device_block.cuh), CUB's radix sort for the keys. Throws d2gs::Error without a
// GPU (or in a build without CUDA); render::kernels::make_emulated_stages() runs the same kernels on the CPU.
#include <memory>

#include "d2gs/render/kernels/stages.hpp"

namespace d2gs::cuda {

std::unique_ptr<render::kernels::StageRunner> make_device_stages();

}  // namespace d2gs::cuda
