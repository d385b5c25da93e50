#pragma once
// Adaptive density control (train/densify.cpp) as kernels. The per-Gaussian arithmetic is
// train/densify_math.hpp's, which the CPU calls too, so results are the CPU's bit for bit.
//  * GradientStatsKernel: GradientStats::add, one thread per Gaussian.
//  * DensifyFlagsKernel: one thread per Gaussian writes five 0/1 flags into five segments of one array
//    of 5n ints: [kept original | emitted clone | emitted split child | split | cloned]. One inclusive
//    scan of the 5n values (render/kernels/scan_kernels.hpp) then gives every emitted row its place in the
//    CPU's order [kept originals, clones, first children, second children, …] (pruned rows removed), and
//    each split Gaussian its rank among all split ones (which numbers its normals).
//  * The normals of the split: the CPU draws 3 per child from its Rng stream (copy-major, then split
//    rank, then axis) by Marsaglia's polar method, which consumes pairs of uniforms and rejects some.
//    All densification draws are normals, so the stream is pair-aligned from the start: whether the p-th
//    pair is accepted depends on that pair alone. PolarCountKernel: thread j counts the accepted pairs
//    among pairs [32j, 32j + 32), from the state jumped 64·j draws ahead (xoshiro_jump.hpp, the dropout
//    kernel's table); the counts are scanned; PolarNormalsKernel redraws each chunk and writes the q-th
//    accepted pair's u·f and v·f as normals h + 2q and h + 2q + 1 (h = 1 when the stream held a spare,
//    which is normal 0), and the thread of the last pair needed writes the stream's state after it and
//    its v·f (Rng's spare, held when the count of pair-drawn normals is odd).
//  * DensifyScatterKernel: one thread per Gaussian writes its kept row, its clone, its children (model
//    rows; the moments copied for kept rows, zero for new ones) and each row's source index.
//  * OpacityResetKernel: reset_opacity, one thread per Gaussian: the logit capped, its Adam moments zeroed.
#include <stdint.h>

#include "d2gs/render/kernels/block.hpp"
#include "d2gs/train/densify_math.hpp"
#include "d2gs/train/kernels/dropout_kernels.hpp"
#include "d2gs/train/kernels/xoshiro_jump.hpp"

namespace d2gs::train_kernels {

struct GradientStatsArgs {
  int n = 0;
  const float* grad_mean2d_ndc = nullptr;  // n x 2
  const int* radii = nullptr;              // n
  float* sum = nullptr;                    // n
  float* count = nullptr;                  // n
};

D2GS_HD void gradient_stats_thread(int i, const GradientStatsArgs& a) {
  add_gradient_stat(i, a.grad_mean2d_ndc, a.radii, a.sum, a.count);
}
using GradientStatsKernel = render::kernels::PerItemKernel<GradientStatsArgs, gradient_stats_thread>;

// The segments of the flag array (each n ints).
enum DensifySegment : int { kKeptSegment = 0, kCloneSegment, kChildSegment, kSplitSegment, kClonedSegment, kSegments };

struct DensifyFlagsArgs {
  int n = 0;
  bool select = true;  // false: prune only (prune_by_opacity)
  const float* grad_sum = nullptr;    // n
  const float* grad_count = nullptr;  // n
  const float* log_scales = nullptr;  // n x 3
  const float* opacity_logits = nullptr;  // n
  float grad_threshold = 0;
  float size_limit = 0;  // percent_dense · extent
  float min_opacity = 0;
  int* flags = nullptr;  // kSegments · n
};

D2GS_HD void densify_flags_thread(int i, const DensifyFlagsArgs& a) {
  const bool selected = a.select && densify_selected(gradient_stat_mean(a.grad_sum[i], a.grad_count[i]), a.grad_threshold);
  const bool clone = selected && densify_clones(a.log_scales + 3 * i, a.size_limit);
  const bool split = selected && !clone;
  const bool alive = !densify_prunes(a.opacity_logits[i], a.min_opacity);
  const int n = a.n;
  a.flags[kKeptSegment * n + i] = !split && alive;
  a.flags[kCloneSegment * n + i] = clone && alive;
  a.flags[kChildSegment * n + i] = split && alive;
  a.flags[kSplitSegment * n + i] = split;
  a.flags[kClonedSegment * n + i] = clone;
}
using DensifyFlagsKernel = render::kernels::PerItemKernel<DensifyFlagsArgs, densify_flags_thread>;

inline constexpr int kPairsPerThread = kDrawsPerThread / 2;

struct PolarArgs {
  int n = 0;                         // threads: chunks of kPairsPerThread pairs
  uint64_t state[4] = {0, 0, 0, 0};  // the stream before the first pair
  const uint64_t* jumps = nullptr;   // dropout_jump_table(): kDrawsPerThread · 2^b draws
  int* counts = nullptr;             // n: accepted pairs per chunk (PolarCountKernel), then scanned
  // PolarNormalsKernel:
  int normals_count = 0;             // normals wanted
  int spare_first = 0;               // 1: normal 0 is the stream's held spare
  float spare = 0;
  float* normals = nullptr;          // normals_count, rounded to float as the CPU uses them
  uint64_t* end_state = nullptr;     // 4 words: the stream after the last pair used
  double* end_spare = nullptr;       // 1: that pair's v·f
};

// The state of chunk j's first pair.
D2GS_HD void polar_chunk_state(int j, const PolarArgs& a, uint64_t* s) {
  for (int k = 0; k < 4; ++k) s[k] = a.state[k];
  for (int b = 0; b < kJumpBits; ++b)
    if ((j >> b) & 1) xoshiro_apply(s, a.jumps + 4 * b);
}

D2GS_HD void polar_count_thread(int j, const PolarArgs& a) {
  uint64_t s[4];
  polar_chunk_state(j, a, s);
  int accepted = 0;
  for (int p = 0; p < kPairsPerThread; ++p) {
    const double u = xoshiro_uniform(s);
    const double v = xoshiro_uniform(s);
    double first, second;
    if (polar_normals(u, v, &first, &second)) ++accepted;
  }
  a.counts[j] = accepted;
}
using PolarCountKernel = render::kernels::PerItemKernel<PolarArgs, polar_count_thread>;

D2GS_HD void polar_normals_thread(int j, const PolarArgs& a) {
  if (j == 0 && a.spare_first) a.normals[0] = a.spare;
  const int pairs = (a.normals_count - a.spare_first + 1) / 2;  // accepted pairs needed
  int q = j > 0 ? a.counts[j - 1] : 0;                          // accepted pairs before this chunk
  if (q >= pairs) return;
  uint64_t s[4];
  polar_chunk_state(j, a, s);
  for (int p = 0; p < kPairsPerThread && q < pairs; ++p) {
    const double u = xoshiro_uniform(s);
    const double v = xoshiro_uniform(s);
    double first, second;
    if (!polar_normals(u, v, &first, &second)) continue;
    const int m = a.spare_first + 2 * q;
    a.normals[m] = static_cast<float>(first);
    if (m + 1 < a.normals_count) a.normals[m + 1] = static_cast<float>(second);
    if (q == pairs - 1) {
      for (int k = 0; k < 4; ++k) a.end_state[k] = s[k];
      *a.end_spare = second;
    }
    ++q;
  }
}
using PolarNormalsKernel = render::kernels::PerItemKernel<PolarArgs, polar_normals_thread>;

// A Gaussians-shaped set of arrays (model, exp_avg, exp_avg_sq): means, log_scales, quats,
// opacity_logits, sh_dc, sh_rest.
inline constexpr int kAttributes = 6;
inline constexpr int kTensors = 3;  // the model and Adam's two moments

struct DensifyScatterArgs {
  int n = 0;
  int children = 2;
  float shrink = 0;                       // split_log_shrink(children)
  int width[kAttributes] = {3, 3, 4, 1, 3, 0};
  const float* in[kTensors][kAttributes] = {};
  float* out[kTensors][kAttributes] = {};
  const int* scanned = nullptr;           // the inclusive scan of DensifyFlagsKernel's flags
  const float* normals = nullptr;         // 3 · children · split
  uint32_t* source = nullptr;             // out: the old row of every new row
};

// Row `dst` of tensor `t` ← row `src` of the input (copy) or zero.
D2GS_HD void densify_copy_row(const DensifyScatterArgs& a, int t, int src, int dst, bool zero) {
  for (int k = 0; k < kAttributes; ++k) {
    const int w = a.width[k];
    for (int c = 0; c < w; ++c) a.out[t][k][dst * w + c] = zero ? 0.0f : a.in[t][k][src * w + c];
  }
}

D2GS_HD void densify_scatter_thread(int i, const DensifyScatterArgs& a) {
  const int n = a.n;
  const int* f = a.scanned;
  // Inclusive scans: the segment's entry before i is the exclusive prefix.
  const auto before = [&](int segment, int i_) { return segment * n + i_ > 0 ? f[segment * n + i_ - 1] : 0; };
  const auto flag = [&](int segment) { return f[segment * n + i] - before(segment, i); };
  const int clone_end = f[kCloneSegment * n + n - 1];
  const int children_alive = f[kChildSegment * n + n - 1] - clone_end;
  const int split_total = f[kSplitSegment * n + n - 1] - f[kChildSegment * n + n - 1];
  if (flag(kKeptSegment)) {
    const int dst = before(kKeptSegment, i);
    for (int t = 0; t < kTensors; ++t) densify_copy_row(a, t, i, dst, false);
    a.source[dst] = static_cast<uint32_t>(i);
  }
  if (flag(kCloneSegment)) {
    const int dst = before(kCloneSegment, i);  // kept_end + clones before i
    densify_copy_row(a, 0, i, dst, false);
    for (int t = 1; t < kTensors; ++t) densify_copy_row(a, t, i, dst, true);
    a.source[dst] = static_cast<uint32_t>(i);
  }
  if (flag(kChildSegment)) {
    const int rank = before(kSplitSegment, i) - f[kChildSegment * n + n - 1];  // among all split Gaussians
    for (int c = 0; c < a.children; ++c) {
      const int dst = before(kChildSegment, i) + c * children_alive;
      densify_copy_row(a, 0, i, dst, false);
      split_child(a.in[0][0] + 3 * i, a.in[0][1] + 3 * i, a.in[0][2] + 4 * i,
                  a.normals + 3 * (c * split_total + rank), a.shrink, a.out[0][0] + 3 * dst, a.out[0][1] + 3 * dst);
      for (int t = 1; t < kTensors; ++t) densify_copy_row(a, t, i, dst, true);
      a.source[dst] = static_cast<uint32_t>(i);
    }
  }
}
using DensifyScatterKernel = render::kernels::PerItemKernel<DensifyScatterArgs, densify_scatter_thread>;

struct OpacityResetArgs {
  int n = 0;
  float cap = 0.0f;             // inverse_sigmoid(ceiling), computed on the host as reset_opacity does
  float* logits = nullptr;      // n
  float* exp_avg = nullptr;     // n: the opacity's Adam moments
  float* exp_avg_sq = nullptr;  // n
};

D2GS_HD void opacity_reset_thread(int i, const OpacityResetArgs& a) {
  a.logits[i] = reset_opacity_logit(a.logits[i], a.cap);
  a.exp_avg[i] = 0.0f;
  a.exp_avg_sq[i] = 0.0f;
}

using OpacityResetKernel = render::kernels::PerItemKernel<OpacityResetArgs, opacity_reset_thread>;

}  // namespace d2gs::train_kernels
