#pragma once
// The host side of the densification edits (densify_and_prune, prune_by_opacity, reset_opacity of train/densify.hpp)
// over a backend of render/kernels/pipeline.hpp, written once: the flags kernel, one scan of the flags,
// the split's normals from the CPU's Rng stream (counted, scanned, drawn), the scatter into new arrays.
// Host arrays in and out; the host reads back only scalars (the totals of the scan, whether enough
// accepted pairs were counted) besides the results. Same results as the CPU bit for bit, rng included.
#include <cstdint>
#include <utility>
#include <vector>

#include "d2gs/core/error.hpp"
#include "d2gs/core/random.hpp"
#include "d2gs/model/gaussians.hpp"
#include "d2gs/render/kernels/block.hpp"
#include "d2gs/render/kernels/pipeline.hpp"
#include "d2gs/train/adam.hpp"
#include "d2gs/train/densify.hpp"
#include "d2gs/train/kernels/densify_kernels.hpp"
#include "d2gs/train/kernels/per_gaussian_pipeline.hpp"

namespace d2gs::train_kernels {

template <class Backend>
class DensifyPipeline {
public:
  explicit DensifyPipeline(Backend& backend) : backend_(backend) {}

  DensifyReport densify_and_prune(Gaussians& model, AdamState& adam, GradientStats& stats, float extent,
                                  const DensifyOptions& options, Rng& rng) {
    if (options.split_children < 1) fail("densification: split_children must be at least 1");
    return run(model, adam, stats, true, options.grad_threshold, options.percent_dense * extent,
               options.min_opacity, options.split_children, &rng);
  }

  DensifyReport prune_by_opacity(Gaussians& model, AdamState& adam, GradientStats& stats, float min_opacity) {
    return run(model, adam, stats, false, 0.0f, 0.0f, min_opacity, 1, nullptr);
  }

  // reset_opacity: every logit capped at inverse_sigmoid(ceiling), the opacity's moments zeroed.
  void reset_opacity(Gaussians& model, AdamState& adam, float ceiling) {
    const std::size_t n = model.opacity_logits.size();
    if (adam.exp_avg.opacity_logits.size() != n || adam.exp_avg_sq.opacity_logits.size() != n)
      fail("opacity reset: {} opacities, {} and {} moments", n, adam.exp_avg.opacity_logits.size(),
           adam.exp_avg_sq.opacity_logits.size());
    if (n == 0) return;
    Array<float> logits, m, v;
    backend_.upload(logits, model.opacity_logits.data(), n);
    backend_.upload(m, adam.exp_avg.opacity_logits.data(), n);
    backend_.upload(v, adam.exp_avg_sq.opacity_logits.data(), n);
    OpacityResetArgs a;
    a.n = static_cast<int>(n);
    a.cap = inverse_sigmoid(ceiling);
    a.logits = logits.data();
    a.exp_avg = m.data();
    a.exp_avg_sq = v.data();
    render::kernels::launch_per_item<OpacityResetKernel>(backend_, static_cast<long long>(n), a);
    backend_.download(model.opacity_logits, logits, n);
    backend_.download(adam.exp_avg.opacity_logits, m, n);
    backend_.download(adam.exp_avg_sq.opacity_logits, v, n);
  }

private:
  template <class T>
  using Array = typename Backend::template Array<T>;

  static std::vector<float>* attribute(Gaussians& g, int k) {
    std::vector<float>* a[kAttributes] = {&g.means, &g.log_scales, &g.quats, &g.opacity_logits, &g.sh_dc, &g.sh_rest};
    return a[k];
  }

  // The split's normals (3 per child, the CPU's order and draws) into normals_; rng left where the CPU's is.
  void draw_normals(int count, Rng& rng) {
    const Rng::State before = rng.state();
    PolarArgs a;
    for (int k = 0; k < 4; ++k) a.state[k] = before.words[k];
    const auto& table = dropout_jump_table();
    backend_.upload(jumps_, table.data(), table.size());
    a.jumps = jumps_.data();
    a.normals_count = count;
    a.spare_first = before.has_spare ? 1 : 0;
    a.spare = static_cast<float>(before.spare);
    const long long pairs = (count - a.spare_first + 1) / 2;
    // About 4/π pairs per accepted one; count more chunks until enough pairs are accepted.
    long long chunks = (pairs * 5 / 4 + 64) / kPairsPerThread + 1;
    for (;;) {
      if (chunks >= (1LL << kJumpBits)) fail("densification kernel: {} normals exceed the jump table", count);
      a.n = static_cast<int>(chunks);
      counts_.resize(static_cast<std::size_t>(chunks));
      a.counts = counts_.data();
      render::kernels::launch_per_item<PolarCountKernel>(backend_, chunks, a);
      render::kernels::inclusive_scan(backend_, counts_.data(), a.n, scan_levels_);
      if (backend_.read(counts_, static_cast<std::size_t>(chunks - 1)) >= pairs) break;
      chunks *= 2;
    }
    normals_.resize(static_cast<std::size_t>(count));
    end_state_.resize(4);
    end_spare_.resize(1);
    a.normals = normals_.data();
    a.end_state = end_state_.data();
    a.end_spare = end_spare_.data();
    render::kernels::launch_per_item<PolarNormalsKernel>(backend_, chunks, a);
    std::vector<uint64_t> words;
    backend_.download(words, end_state_, 4);
    Rng::State after = before;
    for (int k = 0; k < 4; ++k) after.words[k] = words[static_cast<std::size_t>(k)];
    after.spare = backend_.read(end_spare_, 0);
    after.has_spare = (count - a.spare_first) % 2 == 1;
    rng.set_state(after);
  }

  DensifyReport run(Gaussians& model, AdamState& adam, GradientStats& stats, bool select, float grad_threshold,
                    float size_limit, float min_opacity, int children, Rng* rng) {
    const std::size_t n = model.size();
    Gaussians* tensors[kTensors] = {&model, &adam.exp_avg, &adam.exp_avg_sq};
    for (auto* t : tensors)
      if (t->size() != n || t->sh_rest.size() != model.sh_rest.size() || stats.size() != n)
        fail("densification: model ({}), moments ({}, {}) and statistics ({}) are not aligned", n,
             adam.exp_avg.size(), adam.exp_avg_sq.size(), stats.size());
    if (n > static_cast<std::size_t>((1u << 31) - 1) / kSegments)
      fail("densification kernels: {} Gaussians exceed the int32 indices", n);
    DensifyReport report;
    report.before = n;
    if (n == 0) {
      stats.reset(0);
      return report;
    }
    const int nn = static_cast<int>(n);
    const int width[kAttributes] = {3, 3, 4, 1, 3, 3 * model.sh_rest_count()};
    for (int t = 0; t < kTensors; ++t)
      for (int k = 0; k < kAttributes; ++k)
        backend_.upload(in_[t][k], attribute(*tensors[t], k)->data(), n * static_cast<std::size_t>(width[k]));
    backend_.upload(sum_, stats.sums().data(), n);
    backend_.upload(count_, stats.counts().data(), n);

    DensifyFlagsArgs f;
    f.n = nn;
    f.select = select;
    f.grad_sum = sum_.data();
    f.grad_count = count_.data();
    f.log_scales = in_[0][1].data();
    f.opacity_logits = in_[0][3].data();
    f.grad_threshold = grad_threshold;
    f.size_limit = size_limit;
    f.min_opacity = min_opacity;
    flags_.resize(static_cast<std::size_t>(kSegments) * n);
    f.flags = flags_.data();
    render::kernels::launch_per_item<DensifyFlagsKernel>(backend_, nn, f);
    render::kernels::inclusive_scan(backend_, flags_.data(), kSegments * nn, scan_levels_);
    int end[kSegments];
    for (int s = 0; s < kSegments; ++s) end[s] = backend_.read(flags_, static_cast<std::size_t>(s) * n + n - 1);
    const long long kept = end[kKeptSegment], clones = end[kCloneSegment] - end[kKeptSegment];
    const long long children_alive = end[kChildSegment] - end[kCloneSegment];
    const long long split = end[kSplitSegment] - end[kChildSegment];
    const long long cloned = end[kClonedSegment] - end[kSplitSegment];
    const long long after = kept + clones + children * children_alive;
    if (after > (1LL << 31) - 1 || 3LL * children * split > (1LL << 31) - 1)
      fail("densification kernels: {} Gaussians after densification exceed the int32 indices", after);

    if (split > 0) draw_normals(static_cast<int>(3 * children * split), *rng);

    DensifyScatterArgs d;
    d.n = nn;
    d.children = children;
    d.shrink = split_log_shrink(children);
    const std::size_t rows = static_cast<std::size_t>(after);
    for (int t = 0; t < kTensors; ++t)
      for (int k = 0; k < kAttributes; ++k) {
        d.width[k] = width[k];
        d.in[t][k] = in_[t][k].data();
        out_[t][k].resize(rows * static_cast<std::size_t>(width[k]));
        d.out[t][k] = out_[t][k].data();
      }
    d.scanned = flags_.data();
    d.normals = split > 0 ? normals_.data() : nullptr;
    source_.resize(rows);
    d.source = source_.data();
    render::kernels::launch_per_item<DensifyScatterKernel>(backend_, nn, d);

    for (int t = 0; t < kTensors; ++t)
      for (int k = 0; k < kAttributes; ++k)
        backend_.download(*attribute(*tensors[t], k), out_[t][k], rows * static_cast<std::size_t>(width[k]));
    backend_.download(report.source, source_, rows);
    stats.reset(rows);
    report.cloned = static_cast<std::size_t>(cloned);
    report.split = static_cast<std::size_t>(split);
    report.pruned = static_cast<std::size_t>(static_cast<long long>(n) + cloned + children * split - split - after);
    report.after = rows;
    return report;
  }

  Backend& backend_;
  Array<float> in_[kTensors][kAttributes], out_[kTensors][kAttributes];
  Array<float> sum_, count_, normals_;
  Array<int> flags_, counts_;
  Array<uint64_t> jumps_, end_state_;
  Array<double> end_spare_;
  Array<std::uint32_t> source_;
  std::vector<Array<int>> scan_levels_;
};

}  // namespace d2gs::train_kernels
