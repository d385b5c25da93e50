#pragma once
// Which backend a command runs on: `--device cpu|cuda|auto` of d2gs train, render and eval, and what
// `d2gs info` reports. The CPU backend is the reference and runs everything. The CUDA backend
// (render/cuda/, render/kernels/) renders, forward and backward, on the device, and `train --device cuda`
// runs the whole step there (train/kernels/device_step.hpp; with --regularisers only the rasterizer, the rest
// on the CPU). `auto` takes CUDA for both wherever a device exists; without one, the CPU, and says why.
#include <memory>
#include <string>
#include <string_view>

namespace d2gs::render {

class Rasterizer;

// Emulated: the CUDA backend's kernels run on the CPU by the emulator (render/kernels/emulate.hpp) in place
// of the GPU, through the same host code (kernels/kernel_rasterizer.hpp): the GPU's logic without a GPU, for
// checking the kernels over whole commands (a training run's scores against the CPU's). Far slower than
// either backend (every thread of every block in turn); never chosen by `auto`.
enum class DeviceRequest { Cpu, Cuda, Auto, Emulated };
enum class Device { Cpu, Cuda, Emulated };

// "cpu", "cuda", "auto", "emulated"; anything else is a d2gs::Error naming the option.
DeviceRequest parse_device_request(std::string_view word);
const char* to_string(DeviceRequest request);
const char* to_string(Device device);

// What a command would run on, and why.
struct DeviceChoice {
  Device device = Device::Cpu;
  std::string description;  // e.g. "CPU (AVX2 tile loops, 2 OpenMP threads)"
  std::string reason;       // why `auto` chose the CPU; empty when nothing was passed over
};

// What a command runs on the backend: rendering (d2gs render, eval: the rasterizer's forward) or
// training steps (d2gs train).
enum class DeviceWork { Render, Train };

// The backend for `request` and `work`. `cuda` without a usable device is a one-line d2gs::Error
// ("--device cuda: <why>"). `auto` takes CUDA wherever a device exists, else the CPU with `reason`. On
// CUDA a training step is the device-resident step (with --regularisers the rasterizer alone; the trainer's
// choice, by method; the description says so).
DeviceChoice choose_device(DeviceRequest request, DeviceWork work);

// The rasterizer of `choice`: the CPU reference, or the CUDA backend's kernels on device 0 or in the emulator
// (render/kernels/kernel_rasterizer.hpp).
std::unique_ptr<Rasterizer> make_rasterizer(const DeviceChoice& choice);

// The CPU backend in words: its tile-loop level and OpenMP thread count.
std::string describe_cpu_backend();

}  // namespace d2gs::render
