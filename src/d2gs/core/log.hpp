#pragma once
// Logging: spdlog, one line per message, to stderr. `set_verbosity` is called once by the CLI.
#include <spdlog/spdlog.h>

namespace d2gs {

enum class Verbosity { Quiet, Normal, Verbose };
void set_verbosity(Verbosity v);

}  // namespace d2gs
