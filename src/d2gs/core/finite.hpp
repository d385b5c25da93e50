#pragma once
// Whether every value of an array is finite (neither NaN nor ±infinity): the trainer's guard on the gradients
// and parameters of every iteration (≈ 3 M values at fern's model size), so it is vectorised and, above 65 536
// values, parallel. The answer does not depend on the thread count.
#include <cstddef>
#include <vector>

namespace d2gs {

bool all_finite(const float* values, std::size_t count);
inline bool all_finite(const std::vector<float>& values) { return all_finite(values.data(), values.size()); }

}  // namespace d2gs
