#include "d2gs/model/rows.hpp"

#include <algorithm>
#include <array>

#include "d2gs/core/error.hpp"

namespace d2gs {
namespace {

// The six attribute arrays of a model with their values per row, in a fixed order.
template <typename G, typename V = std::conditional_t<std::is_const_v<G>, const std::vector<float>, std::vector<float>>>
std::array<std::pair<V*, std::size_t>, 6> attributes(G& g) {
  const std::size_t rest = static_cast<std::size_t>(g.sh_rest_count()) * 3;
  return {{{&g.means, 3}, {&g.log_scales, 3}, {&g.quats, 4}, {&g.opacity_logits, 1}, {&g.sh_dc, 3}, {&g.sh_rest, rest}}};
}

std::ptrdiff_t off(std::size_t row, std::size_t per) { return static_cast<std::ptrdiff_t>(row * per); }

}  // namespace

void keep_rows(Gaussians& g, const std::vector<std::uint8_t>& keep) {
  const std::size_t n = g.size();
  if (keep.size() != n) fail("keep_rows: {} flags for {} Gaussians", keep.size(), n);
  for (auto [a, per] : attributes(g)) {
    std::size_t out = 0;
    for (std::size_t i = 0; i < n; ++i) {
      if (!keep[i]) continue;
      if (out != i) std::copy_n(a->begin() + off(i, per), per, a->begin() + off(out, per));
      ++out;
    }
    a->resize(out * per);
  }
}

Gaussians gather_rows(const Gaussians& g, const std::vector<std::uint32_t>& indices) {
  const std::size_t n = g.size();
  for (auto i : indices)
    if (i >= n) fail("gather_rows: index {} out of range ({} Gaussians)", i, n);
  Gaussians out;
  out.resize(indices.size(), g.sh_degree);
  const auto from = attributes(g);
  const auto to = attributes(out);
  for (std::size_t k = 0; k < from.size(); ++k) {
    const std::size_t per = from[k].second;
    for (std::size_t r = 0; r < indices.size(); ++r)
      std::copy_n(from[k].first->begin() + off(indices[r], per), per, to[k].first->begin() + off(r, per));
  }
  return out;
}

void append_rows(Gaussians& g, const Gaussians& tail) {
  if (tail.sh_degree != g.sh_degree) fail("append_rows: SH degree {} vs {}", tail.sh_degree, g.sh_degree);
  const auto from = attributes(tail);
  const auto to = attributes(g);
  for (std::size_t k = 0; k < from.size(); ++k) to[k].first->insert(to[k].first->end(), from[k].first->begin(), from[k].first->end());
}

void zero_values(Gaussians& g) {
  for (auto [a, per] : attributes(g)) std::fill(a->begin(), a->end(), 0.0f);
}

}  // namespace d2gs
