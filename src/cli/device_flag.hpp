#pragma once
// The --device flag of d2gs render and eval (d2gs train takes it from its option table): cpu, cuda or
// auto (render/device_choice.hpp).
#include <string>

#include <CLI/CLI.hpp>

#include "d2gs/render/device_choice.hpp"

namespace d2gs::cli {

// Adds --device to `cmd`, stored in `word` (default "auto").
void add_device_flag(CLI::App& cmd, std::string& word);
// The backend for `word`: a one-line d2gs::Error for `cuda` that cannot be had. Call it before any work.
render::DeviceChoice resolve_device_flag(const std::string& word, render::DeviceWork work);
// For `auto` that took the CPU, an info line saying why. Call it once the inputs are checked, so that an
// error about them stays one line.
void log_device_choice(const render::DeviceChoice& choice);

}  // namespace d2gs::cli
