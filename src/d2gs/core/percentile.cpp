#include "d2gs/core/percentile.hpp"

#include <algorithm>
#include <cmath>
#include <cstddef>

#include "d2gs/core/error.hpp"

namespace d2gs {

template <typename T>
double percentile(std::vector<T> values, double q) {
  if (values.empty()) fail("percentile of an empty set");
  std::sort(values.begin(), values.end());
  const double pos = std::clamp(q, 0.0, 100.0) / 100.0 * static_cast<double>(values.size() - 1);
  const auto lo = static_cast<std::size_t>(std::floor(pos));
  const auto hi = std::min(lo + 1, values.size() - 1);
  const double frac = pos - static_cast<double>(lo);
  return static_cast<double>(values[lo]) + frac * (static_cast<double>(values[hi]) - static_cast<double>(values[lo]));
}

template double percentile<float>(std::vector<float> values, double q);
template double percentile<double>(std::vector<double> values, double q);

}  // namespace d2gs
