#pragma once
// The one error type of d2gs. Its message is a single line that names the file (or option) and the
// problem, e.g. "fern/poses_bounds.npy: expected 17 columns, found 14". The command-line program
// prints it as "d2gs: error: <message>" and exits non-zero; library code never aborts on bad input.
#include <filesystem>
#include <stdexcept>
#include <string>
#include <string_view>
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

// File content quoted in a message, made printable: bytes outside printable ASCII (and outside valid
// UTF-8 characters) become \xNN, so a NUL cannot cut the message short nor raw binary reach the
// terminal; more than `max_bytes` bytes of input are cut, with "..." after them.
// fail_file(path, "line {}: '{}' is not a number", n, printable(token)).
std::string printable(std::string_view text, std::size_t max_bytes = 60);

}  // namespace d2gs
