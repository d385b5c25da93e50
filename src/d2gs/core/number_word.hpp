#pragma once
// A command-line word as a number: the one reading of d2gs train's number options (train/options.cpp) and of
// every other command's (src/cli/option_checks.hpp). The whole word must be the number, in the type's range:
// no empty word, no leading space, no sign on an unsigned type, no hexadecimal or octal, nothing clamped to the
// type's largest value, and for a floating type a finite value ("nan", "inf" and overflow are refused).
#include <charconv>
#include <cmath>
#include <string>
#include <string_view>
#include <system_error>
#include <type_traits>

#include <fmt/format.h>

namespace d2gs {

// Reads `word` into `value`; returns what is wrong with it ("'' is not an integer"), empty when nothing is.
template <typename T>
std::string number_word_problem(std::string_view word, T& value) {
  static_assert(std::is_arithmetic_v<T> && !std::is_same_v<T, bool>);
  const char* end = word.data() + word.size();
  const auto [ptr, ec] = std::from_chars(word.data(), end, value);
  if (ec != std::errc() || ptr != end) {
    if constexpr (std::is_integral_v<T>)
      return fmt::format("'{}' is not {}", word, std::is_unsigned_v<T> ? "a whole number ≥ 0" : "an integer");
    else
      return fmt::format("'{}' is not a number", word);
  }
  if constexpr (std::is_floating_point_v<T>)  // from_chars reads "nan", "inf" and overflows to inf
    if (!std::isfinite(value)) return fmt::format("'{}' is not a finite number", word);
  return {};
}

}  // namespace d2gs
