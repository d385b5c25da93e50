#pragma once
// Feature tracks: pairwise matches joined across views by union-find. A track is one world point seen
// by several views; a component that holds two different keypoints of the same view is inconsistent
// (some match in it is wrong) and is dropped.
#include <vector>

#include "d2gs/geometry/matching.hpp"

namespace d2gs {

struct TrackObservation {
  int view = 0;     // position in the list of views given to build_tracks
  int feature = 0;  // keypoint index in that view
};
using Track = std::vector<TrackObservation>;  // sorted by view

struct PairMatches {
  int view_a = 0, view_b = 0;
  std::vector<FeatureMatch> matches;
};

struct TrackStats {
  std::size_t tracks = 0;          // kept (≥ 2 views, consistent)
  std::size_t inconsistent = 0;    // dropped: two keypoints of one view
};

// Tracks of length ≥ 2, ordered by their smallest (view, feature) node, so the result does not depend
// on the order of the pairs. `features_per_view[v]` = keypoint count of view v.
std::vector<Track> build_tracks(const std::vector<std::size_t>& features_per_view, const std::vector<PairMatches>& pairs,
                                TrackStats* stats = nullptr);

}  // namespace d2gs
