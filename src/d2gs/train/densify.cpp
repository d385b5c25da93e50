#include "d2gs/train/densify.hpp"

#include <algorithm>
#include <cmath>

#include "d2gs/core/error.hpp"
#include "d2gs/model/rows.hpp"
#include "d2gs/train/densify_math.hpp"
#include "d2gs/render/activations.hpp"

namespace d2gs {
namespace {

void append_zero_moments(AdamState& adam, std::size_t count) {
  Gaussians zeros;
  zeros.resize(count, adam.exp_avg.sh_degree);
  zero_values(zeros);
  append_rows(adam.exp_avg, zeros);
  append_rows(adam.exp_avg_sq, zeros);
}

void keep_everywhere(Gaussians& model, AdamState& adam, const std::vector<std::uint8_t>& keep,
                     std::vector<std::uint32_t>& source) {
  keep_rows(model, keep);
  keep_rows(adam.exp_avg, keep);
  keep_rows(adam.exp_avg_sq, keep);
  std::size_t out = 0;
  for (std::size_t i = 0; i < keep.size(); ++i)
    if (keep[i]) source[out++] = source[i];
  source.resize(out);
}

void check_aligned(const Gaussians& model, const AdamState& adam, const GradientStats& stats) {
  if (adam.exp_avg.size() != model.size() || adam.exp_avg_sq.size() != model.size() || stats.size() != model.size())
    fail("densification: model ({}), moments ({}, {}) and statistics ({}) are not aligned", model.size(),
         adam.exp_avg.size(), adam.exp_avg_sq.size(), stats.size());
}

}  // namespace

void GradientStats::reset(std::size_t n) {
  sum_.assign(n, 0.0f);
  count_.assign(n, 0.0f);
}

void GradientStats::add(const std::vector<float>& grad, const std::vector<int>& radii) {
  const std::size_t n = sum_.size();
  if (grad.size() != 2 * n || radii.size() != n)
    fail("gradient statistics: {} gradients / {} radii for {} Gaussians", grad.size() / 2, radii.size(), n);
  for (std::size_t i = 0; i < n; ++i)
    add_gradient_stat(static_cast<int>(i), grad.data(), radii.data(), sum_.data(), count_.data());
}

std::vector<float> GradientStats::mean() const {
  std::vector<float> m(sum_.size(), 0.0f);
  for (std::size_t i = 0; i < m.size(); ++i) m[i] = gradient_stat_mean(sum_[i], count_[i]);
  return m;
}

DensifyReport densify_and_prune(Gaussians& model, AdamState& adam, GradientStats& stats, float extent,
                                const DensifyOptions& opt, Rng& rng) {
  check_aligned(model, adam, stats);
  if (opt.split_children < 1) fail("densification: split_children must be at least 1");
  DensifyReport report;
  const std::size_t n = model.size();
  report.before = n;
  const auto grads = stats.mean();
  const float size_limit = opt.percent_dense * extent;

  std::vector<std::uint32_t> clone_idx, split_idx;
  for (std::size_t i = 0; i < n; ++i) {
    if (!densify_selected(grads[i], opt.grad_threshold)) continue;
    (densify_clones(&model.log_scales[i * 3], size_limit) ? clone_idx : split_idx)
        .push_back(static_cast<std::uint32_t>(i));
  }

  // Split children: parent mean + R(parent)·(scale ⊙ n), n ~ N(0, I); scale / (0.8·children).
  const Gaussians parents = gather_rows(model, split_idx);
  Gaussians children;
  children.resize(0, model.sh_degree);
  std::vector<std::uint32_t> child_source;
  const float shrink = split_log_shrink(opt.split_children);
  for (int copy = 0; copy < opt.split_children; ++copy) {
    Gaussians c = parents;
    for (std::size_t k = 0; k < c.size(); ++k) {
      float normal[3];
      for (int d = 0; d < 3; ++d) normal[d] = static_cast<float>(rng.normal());
      split_child(&parents.means[k * 3], &parents.log_scales[k * 3], &parents.quats[k * 4], normal, shrink,
                  &c.means[k * 3], &c.log_scales[k * 3]);
    }
    append_rows(children, c);
    child_source.insert(child_source.end(), split_idx.begin(), split_idx.end());
  }

  // [originals, clones, children]; then drop split parents and low-opacity rows.
  std::vector<std::uint32_t> source(n);
  for (std::size_t i = 0; i < n; ++i) source[i] = static_cast<std::uint32_t>(i);
  append_rows(model, gather_rows(model, clone_idx));
  source.insert(source.end(), clone_idx.begin(), clone_idx.end());
  append_rows(model, children);
  source.insert(source.end(), child_source.begin(), child_source.end());
  append_zero_moments(adam, clone_idx.size() + children.size());

  std::vector<std::uint8_t> keep(model.size(), 1);
  for (auto i : split_idx) keep[i] = 0;
  std::size_t pruned = 0;
  for (std::size_t i = 0; i < model.size(); ++i) {
    if (keep[i] && densify_prunes(model.opacity_logits[i], opt.min_opacity)) {
      keep[i] = 0;
      ++pruned;
    }
  }
  keep_everywhere(model, adam, keep, source);
  stats.reset(model.size());
  report.cloned = clone_idx.size();
  report.split = split_idx.size();
  report.pruned = pruned;
  report.after = model.size();
  report.source = std::move(source);
  return report;
}

DensifyReport prune_by_opacity(Gaussians& model, AdamState& adam, GradientStats& stats, float min_opacity) {
  check_aligned(model, adam, stats);
  DensifyReport report;
  report.before = model.size();
  std::vector<std::uint8_t> keep(model.size(), 1);
  std::vector<std::uint32_t> source(model.size());
  for (std::size_t i = 0; i < model.size(); ++i) {
    source[i] = static_cast<std::uint32_t>(i);
    if (densify_prunes(model.opacity_logits[i], min_opacity)) {
      keep[i] = 0;
      ++report.pruned;
    }
  }
  keep_everywhere(model, adam, keep, source);
  stats.reset(model.size());
  report.after = model.size();
  report.source = std::move(source);
  return report;
}

void reset_opacity(Gaussians& model, AdamState& adam, float ceiling) {
  const float cap = inverse_sigmoid(ceiling);
  for (auto& o : model.opacity_logits) o = reset_opacity_logit(o, cap);
  std::fill(adam.exp_avg.opacity_logits.begin(), adam.exp_avg.opacity_logits.end(), 0.0f);
  std::fill(adam.exp_avg_sq.opacity_logits.begin(), adam.exp_avg_sq.opacity_logits.end(), 0.0f);
}

}  // namespace d2gs
