#pragma once
// The one error type of d2gs. Its message is a single line that names the file (or option) and the
// problem, e.g. "fern/poses_bounds.npy: expected 17 columns, found 14". The command-line program
// prints it as "d2gs: error: <message>" and exits non-zero; library code never aborts on bad input.
#include <filesystem>
#include <stdexcept>
#include <string>
#include <utility>

#include <fmt/core.h>
#include <fmt/std.h>

namespace d2gs {

class Error : public std::runtime_error {
public:
  explicit Error(const std::string& message) : std::runtime_error(message) {}
};

// Throws d2gs::Error with a formatted message.
template <typename... Args>
[[noreturn]] void fail(fmt::format_string<Args...> format, Args&&... args) {
  throw Error(fmt::format(format, std::forward<Args>(args)...));
}

// Throws d2gs::Error "<path>: <formatted problem>".
template <typename... Args>
[[noreturn]] void fail_file(const std::filesystem::path& path, fmt::format_string<Args...> format,
                            Args&&... args) {
  throw Error(path.string() + ": " + fmt::format(format, std::forward<Args>(args)...));
}

}  // namespace d2gs
