#include "d2gs/core/json_value.hpp"

#include <algorithm>

#include "d2gs/core/atomic_file.hpp"

namespace d2gs {

nlohmann::json parse_json(std::string_view text, const std::filesystem::path& source) {
  try {
    return nlohmann::json::parse(text.begin(), text.end());
  } catch (const nlohmann::json::exception& e) {
    // nlohmann's messages may quote input containing newlines; errors are one line.
    std::string what = e.what();
    std::replace_if(what.begin(), what.end(), [](char c) { return c == '\n' || c == '\r'; }, ' ');
    fail_file(source, "invalid JSON ({})", what);
  }
}

nlohmann::json read_json_file(const std::filesystem::path& path) { return parse_json(read_file(path), path); }

}  // namespace d2gs
