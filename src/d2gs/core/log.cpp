#include "d2gs/core/log.hpp"

#include <spdlog/sinks/stdout_color_sinks.h>

namespace d2gs {

void set_verbosity(Verbosity v) {
  static auto logger = [] {
    auto l = spdlog::stderr_color_mt("d2gs");
    l->set_pattern("%^[%L]%$ %v");
    spdlog::set_default_logger(l);
    return l;
  }();
  switch (v) {
    case Verbosity::Quiet: logger->set_level(spdlog::level::err); break;
    case Verbosity::Normal: logger->set_level(spdlog::level::info); break;
    case Verbosity::Verbose: logger->set_level(spdlog::level::debug); break;
  }
}

}  // namespace d2gs
