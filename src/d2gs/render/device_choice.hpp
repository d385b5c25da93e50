#pragma once
// Which backend a command runs on: `--device cpu|cuda|auto` of d2gs train, render and eval, and what
// `d2gs info` reports. The CPU backend is the reference and runs everything. The CUDA backend
// (render/cuda/, render/kernels/) runs the stages that exist as kernels (docs/architecture.md, "CUDA
// backend and its CPU emulation"), but not yet a whole training step or render; until it does, `cuda` is
// refused with the reason and `auto` takes the CPU and says why.
#include <string>
#include <string_view>

namespace d2gs::render {

enum class DeviceRequest { Cpu, Cuda, Auto };
enum class Device { Cpu, Cuda };

// "cpu", "cuda", "auto"; anything else is a d2gs::Error naming the option.
DeviceRequest parse_device_request(std::string_view word);
const char* to_string(DeviceRequest request);
const char* to_string(Device device);

// What a command would run on, and why.
struct DeviceChoice {
  Device device = Device::Cpu;
  std::string description;  // e.g. "CPU (AVX2 tile loops, 2 OpenMP threads)"
  std::string reason;       // why `auto` chose the CPU; empty when nothing was passed over
};

// Whether the CUDA backend runs a whole training step and render on the device. False until every
// stage of issue 27 is a kernel; then `auto` chooses CUDA wherever a device exists.
bool cuda_backend_complete();

// The backend for `request`. `cuda` without a usable device, or while the CUDA backend is incomplete, is a
// one-line d2gs::Error ("--device cuda: <why>"); `auto` then takes the CPU and fills `reason`.
DeviceChoice choose_device(DeviceRequest request);

// The CPU backend in words: its tile-loop level and OpenMP thread count.
std::string describe_cpu_backend();

}  // namespace d2gs::render
