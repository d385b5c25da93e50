#pragma once
// The --device flag of d2gs render and eval (d2gs train takes it from its option table): cpu, cuda or
// auto (render/device_choice.hpp).
#include <string>

#include <CLI/CLI.hpp>

#include "d2gs/render/device_choice.hpp"

namespace d2gs::cli {

// Adds --device to `cmd`, stored in `word` (default "auto").
void add_device_flag(CLI::App& cmd, std::string& word);
// The backend for `word`: a one-line d2gs::Error for `cuda` that cannot be had; for `auto` that takes the
// CPU, an info line saying why.
render::DeviceChoice resolve_device_flag(const std::string& word);

}  // namespace d2gs::cli
