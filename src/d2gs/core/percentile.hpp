#pragma once
// The q-th percentile of a set of values as NumPy's np.percentile computes it by default: linear
// interpolation between the two closest ranks of the sorted values, q in [0, 100] (clamped).
#include <cstddef>
#include <vector>

namespace d2gs {

// Float or double values (a braced list of numbers reads as doubles). Throws d2gs::Error for an empty set.
template <typename T = double>
double percentile(std::vector<T> values, double q);

extern template double percentile<float>(std::vector<float> values, double q);
extern template double percentile<double>(std::vector<double> values, double q);

// The k-th smallest of n floats (k < n, counted from 0): the value std::nth_element puts at position k, found
// by a radix selection on the values' order-preserving bit patterns (three passes of histograms, the later
// ones over the few candidates left) in O(n) without reordering or copying the input. -0 counts as below
// +0 (nth_element may return either, and they compare equal). The values must not hold NaN (nth_element's
// order is undefined then); throws d2gs::Error for k >= n or when the value selected is a NaN.
float kth_smallest(const float* values, std::size_t n, std::size_t k);

}  // namespace d2gs
