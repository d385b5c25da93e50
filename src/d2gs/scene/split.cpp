#include "d2gs/scene/split.hpp"

#include "d2gs/core/error.hpp"

namespace d2gs {
long round_half_even(double) { fail("not implemented yet"); }
std::vector<int> linspace_pick(const std::vector<int>&, int) { fail("not implemented yet"); }
Split make_split(const Scene&, const SplitOptions&) { fail("not implemented yet"); }
}  // namespace d2gs
