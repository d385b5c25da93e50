#include "cli/device_flag.hpp"

#include <spdlog/spdlog.h>

#include "cli/option_checks.hpp"

namespace d2gs::cli {

void add_device_flag(CLI::App& cmd, std::string& word) {
  word = "auto";
  add_option(cmd, "--device", word,
             "Backend: cpu (the reference), cuda (an error where no CUDA device exists or this d2gs was built without "
             "CUDA), auto (CUDA where it can, else the CPU, "
             "saying why; `d2gs info` shows the choice), emulated (the CUDA kernels run on the CPU by the emulator "
             "instead of a GPU: slow, for checking them)")
      ->capture_default_str()
      ->check(CLI::IsMember({"cpu", "cuda", "auto", "emulated"}));
}

render::DeviceChoice resolve_device_flag(const std::string& word, render::DeviceWork work) {
  return render::choose_device(render::parse_device_request(word), work);
}

void log_device_choice(const render::DeviceChoice& choice) {
  if (!choice.reason.empty()) spdlog::info("--device auto: using the {}: {}", choice.description, choice.reason);
}

}  // namespace d2gs::cli
