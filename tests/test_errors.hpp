#pragma once
// The message a test expects from a d2gs::Error.
#include <functional>
#include <string>

#include "d2gs/core/error.hpp"

namespace d2gs::test {

// The message of the d2gs::Error that f throws, or "" when it throws none.
inline std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

}  // namespace d2gs::test
