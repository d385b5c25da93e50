#include "d2gs/geometry/tracks.hpp"

#include <algorithm>
#include <map>
#include <numeric>

#include "d2gs/core/error.hpp"

namespace d2gs {

namespace {
struct UnionFind {
  std::vector<std::size_t> parent;
  explicit UnionFind(std::size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), std::size_t{0}); }
  std::size_t find(std::size_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  }
  void unite(std::size_t a, std::size_t b) {
    a = find(a), b = find(b);
    if (a != b) parent[std::max(a, b)] = std::min(a, b);  // the root is the smallest node
  }
};
}  // namespace

std::vector<Track> build_tracks(const std::vector<std::size_t>& features_per_view, const std::vector<PairMatches>& pairs,
                                TrackStats* stats) {
  std::vector<std::size_t> offset(features_per_view.size() + 1, 0);
  for (std::size_t v = 0; v < features_per_view.size(); ++v) offset[v + 1] = offset[v] + features_per_view[v];
  UnionFind uf(offset.back());
  std::vector<std::uint8_t> used(offset.back(), 0);
  for (const auto& p : pairs) {
    if (p.view_a < 0 || p.view_b < 0 || static_cast<std::size_t>(p.view_a) >= features_per_view.size() ||
        static_cast<std::size_t>(p.view_b) >= features_per_view.size() || p.view_a == p.view_b)
      fail("tracks: invalid view pair ({}, {})", p.view_a, p.view_b);
    for (const auto& m : p.matches) {
      if (m.a < 0 || m.b < 0 || static_cast<std::size_t>(m.a) >= features_per_view[static_cast<std::size_t>(p.view_a)] ||
          static_cast<std::size_t>(m.b) >= features_per_view[static_cast<std::size_t>(p.view_b)])
        fail("tracks: match ({}, {}) out of range for views ({}, {})", m.a, m.b, p.view_a, p.view_b);
      const std::size_t na = offset[static_cast<std::size_t>(p.view_a)] + static_cast<std::size_t>(m.a);
      const std::size_t nb = offset[static_cast<std::size_t>(p.view_b)] + static_cast<std::size_t>(m.b);
      used[na] = used[nb] = 1;
      uf.unite(na, nb);
    }
  }
  std::map<std::size_t, Track> by_root;  // ordered by root = smallest node of the component
  for (std::size_t v = 0; v < features_per_view.size(); ++v)
    for (std::size_t f = 0; f < features_per_view[v]; ++f) {
      const std::size_t node = offset[v] + f;
      if (used[node]) by_root[uf.find(node)].push_back({static_cast<int>(v), static_cast<int>(f)});
    }
  std::vector<Track> tracks;
  TrackStats st;
  for (auto& [root, t] : by_root) {
    bool consistent = true;
    for (std::size_t i = 1; i < t.size(); ++i)
      if (t[i].view == t[i - 1].view) consistent = false;  // nodes come sorted by view
    if (!consistent) {
      ++st.inconsistent;
      continue;
    }
    if (t.size() >= 2) tracks.push_back(std::move(t));
  }
  st.tracks = tracks.size();
  if (stats) *stats = st;
  return tracks;
}

}  // namespace d2gs
