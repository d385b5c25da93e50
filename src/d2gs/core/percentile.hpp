#pragma once
// The q-th percentile of a set of values as NumPy's np.percentile computes it by default: linear
// interpolation between the two closest ranks of the sorted values, q in [0, 100] (clamped).
#include <vector>

namespace d2gs {

// Float or double values (a braced list of numbers reads as doubles). Throws d2gs::Error for an empty set.
template <typename T = double>
double percentile(std::vector<T> values, double q);

extern template double percentile<float>(std::vector<float> values, double q);
extern template double percentile<double>(std::vector<double> values, double q);

}  // namespace d2gs
