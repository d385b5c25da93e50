#pragma once
// Checked reads of numbers from JSON (configs, experiment files, recorded run files). nlohmann's
// get<int>() truncates 5.7 to 5 and wraps 4294967301 to 5; these never do: an integer field takes only a
// JSON integer, a value must fit the field's type and lie in [min, max] (the same ranges the command
// line enforces), and a float field takes only a finite number. On failure they throw d2gs::Error
// "key 'NAME': PROBLEM"; callers that know the file prefix it (fail_file(file, "{}", e.what())).
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "d2gs/core/error.hpp"

namespace d2gs {

// Parses JSON text; any failure (syntax, a number too large for a double such as 1e400, nesting too
// deep) throws d2gs::Error "<source>: invalid JSON (...)" on one line. A key that appears twice in one
// object (which nlohmann would let the last one win) is the error "<source>: duplicate key 'K' in PATH".
nlohmann::json parse_json(std::string_view text, const std::filesystem::path& source);
// read_file + parse_json.
nlohmann::json read_json_file(const std::filesystem::path& path);

namespace json_detail {
// The value as written, for messages (a long string or array is cut).
inline std::string shown(const nlohmann::json& v) {
  std::string s = v.dump();
  if (s.size() > 40) s = s.substr(0, 37) + "...";
  return s;
}
// The value with its type, as in "got string \"5\"" (null, which is both: "got null").
inline std::string typed(const nlohmann::json& v) {
  return v.is_null() ? "null" : fmt::format("{} {}", v.type_name(), shown(v));
}
}  // namespace json_detail

// `value` as a T (an integral or floating type) in [min, max].
template <typename T>
T json_number(const nlohmann::json& value, std::string_view key, T min = std::numeric_limits<T>::lowest(),
              T max = std::numeric_limits<T>::max()) {
  static_assert(std::is_arithmetic_v<T> && !std::is_same_v<T, bool>);
  const auto out_of_range = [&]() {
    fail("key '{}': {} is out of range (expected {}..{})", key, json_detail::shown(value), min, max);
  };
  if constexpr (std::is_integral_v<T>) {
    if (value.is_number_float()) fail("key '{}' must be an integer, got {}", key, json_detail::shown(value));
    if (!value.is_number_integer()) fail("key '{}' must be an integer, got {}", key, json_detail::typed(value));
    // nlohmann stores non-negative integers as unsigned, negative ones as signed 64-bit.
    const auto take = [&](auto v) {
      if (!std::in_range<T>(v) || std::cmp_less(v, min) || std::cmp_greater(v, max)) out_of_range();
      return static_cast<T>(v);
    };
    return value.is_number_unsigned() ? take(value.get<std::uint64_t>()) : take(value.get<std::int64_t>());
  } else {
    if (!value.is_number()) fail("key '{}' must be a number, got {}", key, json_detail::typed(value));
    const double d = value.get<double>();
    if (!std::isfinite(d)) fail("key '{}' must be a finite number, got {}", key, json_detail::shown(value));
    if (d < static_cast<double>(min) || d > static_cast<double>(max)) out_of_range();
    return static_cast<T>(d);
  }
}

// `value` as a list of T, each in [min, max].
template <typename T>
std::vector<T> json_number_list(const nlohmann::json& value, std::string_view key,
                                T min = std::numeric_limits<T>::lowest(), T max = std::numeric_limits<T>::max()) {
  if (!value.is_array()) fail("key '{}' must be a list of numbers, got {}", key, json_detail::typed(value));
  std::vector<T> out;
  out.reserve(value.size());
  for (std::size_t i = 0; i < value.size(); ++i)
    out.push_back(json_number<T>(value[i], fmt::format("{}[{}]", key, i), min, max));
  return out;
}

}  // namespace d2gs
