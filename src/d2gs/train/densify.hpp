#pragma once
// Adaptive density control of 3DGS (method.md §2): the screen-space gradient statistic, clone, split,
// prune and opacity reset. Every edit applies the same row operations to the model and to both Adam
// moments (new rows get zero moments), and reports where each new row came from so that any other
// per-Gaussian array (e.g. D²GS's cached density) can be carried along.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "d2gs/core/random.hpp"
#include "d2gs/model/gaussians.hpp"
#include "d2gs/train/adam.hpp"

namespace d2gs {

struct DensifyOptions {
  float grad_threshold = 0.0005f;  // on the mean ‖∂L/∂mean2d‖ in NDC units
  float percent_dense = 0.01f;     // clone if max scale ≤ percent_dense·extent, else split
  float min_opacity = 0.005f;      // prune below
  int split_children = 2;
  float split_scale_divisor = 1.6f;  // child scale = parent scale / (0.8·children)
};

// Mean of ‖∂L/∂mean2d (NDC)‖ over the iterations in which each Gaussian was visible.
class GradientStats {
public:
  void reset(std::size_t n);
  // grad_mean2d_ndc: N×2; radii: N (visible where > 0).
  void add(const std::vector<float>& grad_mean2d_ndc, const std::vector<int>& radii);
  std::vector<float> mean() const;  // 0 where never visible
  std::size_t size() const { return sum_.size(); }
  // Raw sums and counts (checkpoints).
  const std::vector<float>& sums() const { return sum_; }
  const std::vector<float>& counts() const { return count_; }
  void restore(std::vector<float> sums, std::vector<float> counts) {
    sum_ = std::move(sums);
    count_ = std::move(counts);
  }

private:
  std::vector<float> sum_;
  std::vector<float> count_;
};

struct DensifyReport {
  std::size_t cloned = 0, split = 0, pruned = 0, before = 0, after = 0;
  // For every row of the new model, the row of the old model it came from (itself, or its parent).
  std::vector<std::uint32_t> source;
};

// Clone, split, then prune by opacity, in the original order: the result is laid out as
// [kept originals, clones, split children (first copies, then second copies)] minus pruned rows.
// Resets `stats` to the new size.
DensifyReport densify_and_prune(Gaussians& model, AdamState& adam, GradientStats& stats, float scene_extent,
                                const DensifyOptions& options, Rng& rng);

// Removes Gaussians whose opacity is below `min_opacity` (model, moments, stats aligned).
DensifyReport prune_by_opacity(Gaussians& model, AdamState& adam, GradientStats& stats, float min_opacity);

// opacity ← min(opacity, 0.01) and the opacity moments zeroed, as the original's reset.
void reset_opacity(Gaussians& model, AdamState& adam, float ceiling = 0.01f);

}  // namespace d2gs
