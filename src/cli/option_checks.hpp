#pragma once
// The checks of option values outside d2gs train (whose options are checked by their table,
// train/options.cpp), with the same words: a number option takes only a whole word that is a number of its
// type (core/number_word.hpp; CLI11 2.1 alone reads "" as 0, "-1" into an unsigned as 2^64 − 1 and clamps
// 2^64 to 2^64 − 1), a text or path option no empty word, and a range is said as train says it ("≥ 1",
// "in [2, 1000]"). A failed check is a CLI::ValidationError "--NAME: PROBLEM", which main() prints on one
// line as "d2gs: error: COMMAND: --NAME: PROBLEM".
#include <limits>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "d2gs/core/number_word.hpp"

namespace d2gs::cli {

// The word is a number of type T.
template <typename T>
CLI::Validator number_check() {
  return CLI::Validator(
      [](std::string& word) {
        T value{};
        return number_word_problem(word, value);
      },
      "", "number");
}

// The word is a number of type T in [min, max], said as `shown` ("in [2, 1000]", "≥ 1").
template <typename T>
CLI::Validator range_check(T min, T max, std::string shown) {
  return CLI::Validator(
      [min, max, shown](std::string& word) -> std::string {
        T value{};
        if (std::string problem = number_word_problem(word, value); !problem.empty()) return problem;
        if (value < min || value > max) return fmt::format("must be {} (got {})", shown, word);
        return {};
      },
      shown, "range");
}
template <typename T>
CLI::Validator at_least(T min) {
  return range_check<T>(min, std::numeric_limits<T>::max(), fmt::format("≥ {}", min));
}
template <typename T>
CLI::Validator in_range(T min, T max) {
  return range_check<T>(min, max, fmt::format("in [{}, {}]", min, max));
}

// The word is not empty (a path or name given as '' is refused, not taken as "not given").
inline CLI::Validator not_empty() {
  return CLI::Validator(
      [](std::string& word) { return word.empty() ? std::string("must not be empty") : std::string(); }, "",
      "not_empty");
}

// The type of one value of an option bound to a T.
template <typename T>
struct Element {
  using type = T;
};
template <typename T>
struct Element<std::vector<T>> {
  using type = T;
};

// cmd.add_option(names, variable, description) with the check that the variable's type asks for: a number
// (or a list of numbers) number_check, a string (or a list of strings) not_empty. Every option of the commands
// but train is added through here.
template <typename T>
CLI::Option* add_option(CLI::App& cmd, std::string names, T& variable, std::string description) {
  CLI::Option* option = cmd.add_option(std::move(names), variable, std::move(description));
  using Value = typename Element<T>::type;
  if constexpr (std::is_arithmetic_v<Value> && !std::is_same_v<Value, bool>)
    option->check(number_check<Value>());
  else if constexpr (std::is_same_v<Value, std::string>)
    option->check(not_empty());
  return option;
}

}  // namespace d2gs::cli
