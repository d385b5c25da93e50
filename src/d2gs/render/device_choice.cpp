#include "d2gs/render/device_choice.hpp"

#include <fmt/format.h>

#ifdef _OPENMP
#include <omp.h>
#endif

#include "d2gs/core/error.hpp"
#include "d2gs/render/cpu/composite_tiles.hpp"
#include "d2gs/render/cuda/device.hpp"
#include "d2gs/render/cuda/stages.hpp"
#include "d2gs/render/kernels/kernel_rasterizer.hpp"
#include "d2gs/render/rasterizer.hpp"

namespace d2gs::render {

DeviceRequest parse_device_request(std::string_view word) {
  if (word == "cpu") return DeviceRequest::Cpu;
  if (word == "cuda") return DeviceRequest::Cuda;
  if (word == "auto") return DeviceRequest::Auto;
  if (word == "emulated") return DeviceRequest::Emulated;
  fail("option --device must be cpu, cuda, auto or emulated (got '{}')", word);
}

const char* to_string(DeviceRequest request) {
  switch (request) {
    case DeviceRequest::Cpu: return "cpu";
    case DeviceRequest::Cuda: return "cuda";
    case DeviceRequest::Auto: return "auto";
    case DeviceRequest::Emulated: return "emulated";
  }
  return "?";
}

const char* to_string(Device device) {
  switch (device) {
    case Device::Cpu: return "cpu";
    case Device::Cuda: return "cuda";
    case Device::Emulated: return "emulated";
  }
  return "?";
}

std::string describe_cpu_backend() {
#ifdef _OPENMP
  const int threads = omp_get_max_threads();
#else
  const int threads = 1;
#endif
  return fmt::format("CPU ({} tile loops, {} OpenMP thread{})", cpu::tile_kernels_float().isa, threads,
                     threads == 1 ? "" : "s");
}

DeviceChoice choose_device(DeviceRequest request, DeviceWork work) {
  DeviceChoice cpu_choice{Device::Cpu, describe_cpu_backend(), ""};
  if (request == DeviceRequest::Cpu) return cpu_choice;
  if (request == DeviceRequest::Emulated)
    return {Device::Emulated,
            work == DeviceWork::Render
                ? "the CUDA backend's kernels emulated on the CPU (slow: for checking the kernels)"
                : "the CUDA backend's kernels emulated on the CPU: the whole training step, or with "
                  "--regularisers the rasterizer (their hooks on the CPU) (slow: for checking the kernels)",
            ""};
  // Rendering and a training step both run on the device (render/kernels/kernel_rasterizer.hpp,
  // train/kernels/device_step.hpp); with --regularisers a step rasterizes there and runs their hooks here.
  if (cuda::device_count() > 0)
    return {Device::Cuda,
            "CUDA " + cuda::describe_device() +
                (work == DeviceWork::Train
                     ? ": the whole training step, or with --regularisers the rasterizer (their hooks on the CPU)"
                     : ""),
            ""};
  const std::string why = cuda::describe_device();  // "no CUDA device: ...", "this d2gs was built without CUDA"
  if (request == DeviceRequest::Cuda) fail("--device cuda: {}; use --device cpu or auto", why);
  cpu_choice.reason = why;
  return cpu_choice;
}

std::unique_ptr<Rasterizer> make_rasterizer(const DeviceChoice& choice) {
  switch (choice.device) {
    case Device::Cpu: return make_cpu_rasterizer();
    case Device::Emulated: return kernels::make_kernel_rasterizer(kernels::make_emulated_stages(), true);
    case Device::Cuda: break;
  }
  return kernels::make_kernel_rasterizer(cuda::make_device_stages(), true);
}

}  // namespace d2gs::render
