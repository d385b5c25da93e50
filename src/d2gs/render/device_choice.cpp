#include "d2gs/render/device_choice.hpp"

#include <fmt/format.h>

#ifdef _OPENMP
#include <omp.h>
#endif

#include "d2gs/core/error.hpp"
#include "d2gs/render/cpu/composite_tiles.hpp"
#include "d2gs/render/cuda/device.hpp"

namespace d2gs::render {

DeviceRequest parse_device_request(std::string_view word) {
  if (word == "cpu") return DeviceRequest::Cpu;
  if (word == "cuda") return DeviceRequest::Cuda;
  if (word == "auto") return DeviceRequest::Auto;
  fail("option --device must be cpu, cuda or auto (got '{}')", word);
}

const char* to_string(DeviceRequest request) {
  switch (request) {
    case DeviceRequest::Cpu: return "cpu";
    case DeviceRequest::Cuda: return "cuda";
    case DeviceRequest::Auto: return "auto";
  }
  return "?";
}

const char* to_string(Device device) { return device == Device::Cuda ? "cuda" : "cpu"; }

// The kernels that exist (projection, SH, tile intersection, Adam, L1 and what render/kernels/ lists) do
// not yet make a training step: compositing, SSIM, densification, the dropout masks and DAFE are missing.
bool cuda_backend_complete() { return false; }

std::string describe_cpu_backend() {
#ifdef _OPENMP
  const int threads = omp_get_max_threads();
#else
  const int threads = 1;
#endif
  return fmt::format("CPU ({} tile loops, {} OpenMP thread{})", cpu::tile_kernels_float().isa, threads,
                     threads == 1 ? "" : "s");
}

DeviceChoice choose_device(DeviceRequest request) {
  DeviceChoice cpu_choice{Device::Cpu, describe_cpu_backend(), ""};
  if (request == DeviceRequest::Cpu) return cpu_choice;
  // Why CUDA cannot be used, or empty when it can.
  std::string why;
  if (cuda::device_count() == 0)
    why = cuda::describe_device();  // "no CUDA device: ...", "this d2gs was built without CUDA"
  else if (!cuda_backend_complete())
    why = fmt::format("{} found, but the CUDA backend does not yet run a whole training step or render "
                      "(docs/architecture.md)",
                      cuda::describe_device());
  if (why.empty()) return {Device::Cuda, "CUDA " + cuda::describe_device(), ""};
  if (request == DeviceRequest::Cuda) fail("--device cuda: {}; use --device cpu or auto", why);
  cpu_choice.reason = why;
  return cpu_choice;
}

}  // namespace d2gs::render
