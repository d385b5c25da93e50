#pragma once
// DD-Drop's drop probabilities (train/dropout.cpp: dd_drop_probabilities of gaussian_depths) as kernels,
// with the per-Gaussian arithmetic of train/dd_drop_math.hpp (the CPU's):
//
//  - GaussianDepthKernel: one thread per Gaussian: its depth w.r.t. the training camera (Euclidean
//    distance to the centre, or the release's x·R_w2c[:,2]), and a sort key of it: the float's bits made
//    to order as the floats do (float_order_key, core/float_order.hpp), with the Gaussian's index as the value.
//  - the host sorts the keys (CUB's radix sort over 32 bits on the GPU, a stable sort of the same keys in
//    emulation): the minimum and maximum depth and the tertile thresholds are the sorted keys at ranks 0,
//    N − 1, ⌊0.33·N⌋ and ⌊0.67·N⌋ — the values std::minmax_element and kth_smallest (core/percentile) give the CPU.
//  - DdDropProbabilityKernel: one thread per Gaussian: the normalised depth, the layer, and p_i with the
//    density score (host-refreshed kNN scores, uploaded) and the iteration's constants (DdDropTerms).
//
// Sorting by the ordered bits puts −0 before +0 where the CPU's < sees them equal; a threshold or minimum
// of either sign gives the same layers and the same (v − lo)/range, so the probabilities are the CPU's
// bit for bit. Depths must not be NaN (neither the CPU's selection nor the key order defines them).
#include <stdint.h>

#include "d2gs/core/float_order.hpp"
#include "d2gs/render/kernels/block.hpp"
#include "d2gs/train/dd_drop_math.hpp"

namespace d2gs::train_kernels {

struct GaussianDepthArgs {
  int n = 0;
  const float* means = nullptr;  // n x 3
  bool euclidean = false;        // distance to `centre`, else the release's dot product with `axis`
  double centre[3] = {0, 0, 0};  // the camera centre in world coordinates
  double axis[3] = {0, 0, 0};    // the third column of R_world_to_cam
  float* depth = nullptr;        // n
  uint64_t* keys = nullptr;      // n: float_order_key(depth)
  int32_t* index = nullptr;      // n: i
};

D2GS_HD void gaussian_depth_thread(int i, const GaussianDepthArgs& a) {
  const float* m = a.means + 3 * static_cast<long long>(i);
  const float d = a.euclidean ? dd_drop_depth_euclidean(m[0], m[1], m[2], a.centre)
                              : dd_drop_depth_release(m[0], m[1], m[2], a.axis);
  a.depth[i] = d;
  a.keys[i] = float_order_key(d);
  a.index[i] = i;
}
using GaussianDepthKernel = render::kernels::PerItemKernel<GaussianDepthArgs, gaussian_depth_thread>;

struct DdDropProbabilityArgs {
  int n = 0;
  const float* depth = nullptr;           // n
  const uint64_t* sorted_keys = nullptr;  // n: the depths' keys, ascending
  int near_rank = 0, far_rank = 0;        // tertile_rank(n, 0.33), tertile_rank(n, 0.67)
  const float* density_score = nullptr;   // n, in [0, 1] (dense → 1)
  DdDropTerms terms;
  float* probabilities = nullptr;         // n
};

D2GS_HD void dd_drop_probability_thread(int i, const DdDropProbabilityArgs& a) {
  const float lo = float_from_order_key(static_cast<uint32_t>(a.sorted_keys[0]));
  const float hi = float_from_order_key(static_cast<uint32_t>(a.sorted_keys[a.n - 1]));
  const float t1 = float_from_order_key(static_cast<uint32_t>(a.sorted_keys[a.near_rank]));
  const float t2 = float_from_order_key(static_cast<uint32_t>(a.sorted_keys[a.far_rank]));
  const float d = a.depth[i];
  a.probabilities[i] =
      dd_drop_probability(minmax_normalised(d, lo, hi - lo), a.density_score[i], depth_layer(d, t1, t2), a.terms);
}
using DdDropProbabilityKernel = render::kernels::PerItemKernel<DdDropProbabilityArgs, dd_drop_probability_thread>;

}  // namespace d2gs::train_kernels
