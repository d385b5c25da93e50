#pragma once
// The host side of the stages: buffers, the order of the launches, the recursive scan, the sort. Written
// once over a Backend (emulated_stages.cpp: host vectors and the emulator; cuda/stages.cu: device memory,
// kernel<<<>>> and CUB), so CI runs this sequence too, not only the kernel bodies.
//
// A Backend provides: Array<T> (resize(n) grows without keeping contents, data()), launch<Body>(blocks,
// threads, args), upload(array, host pointer, n) (resizes), download(vector, array, n), read(array, i)
// (one value), zero(array, n), and sort_pairs(keys, keys_out, values, values_out, n, end_bit).
#include <cstdint>
#include <cstring>
#include <utility>
#include <vector>

#include "d2gs/core/error.hpp"
#include "d2gs/render/kernels/composite_kernels.hpp"
#include "d2gs/render/kernels/intersect_kernels.hpp"
#include "d2gs/render/kernels/projection_kernels.hpp"
#include "d2gs/render/kernels/scan_kernels.hpp"
#include "d2gs/render/kernels/sh_kernels.hpp"
#include "d2gs/render/kernels/stages.hpp"

namespace d2gs::render::kernels {

// In-place inclusive scan of n ints: block scans, the block totals scanned the same way (one level per
// factor of kScanBlock), then the totals of earlier blocks added. `levels` keeps the totals' buffers.
template <class Backend, class Levels>
void inclusive_scan(Backend& backend, int* data, int n, Levels& levels, std::size_t level = 0) {
  if (n <= 0) return;
  const int blocks = blocks_for(n, kScanBlock);
  if (levels.size() <= level) levels.resize(level + 1);
  levels[level].resize(static_cast<std::size_t>(blocks));
  ScanArgs scan;
  scan.n = n;
  scan.data = data;
  scan.block_sums = levels[level].data();
  backend.template launch<BlockScanKernel>(blocks, kScanBlock, scan);
  if (blocks == 1) return;
  inclusive_scan(backend, levels[level].data(), blocks, levels, level + 1);
  AddBlockOffsetsArgs add;
  add.n = n;
  add.data = data;
  add.scanned_block_sums = levels[level].data();  // levels may have grown: index again
  backend.template launch<AddBlockOffsetsKernel>(blocks, kScanBlock, add);
}

// Bits needed for tile ids 0 .. tiles - 1 (the sort ignores the key bits above 32 + this).
inline int tile_id_bits(int tiles) {
  int bits = 0;
  while ((1LL << bits) < tiles) ++bits;
  return bits;
}

// Launches Kernel<Smooth, Fused> for the run-time choices (both compiled).
template <template <bool, bool> class Kernel, class Backend, class Args>
void launch_composite(Backend& backend, int blocks, const Args& args, bool smooth, bool fused) {
  if (smooth) {
    if (fused)
      backend.template launch<Kernel<true, true>>(blocks, kCompositeBlock, args);
    else
      backend.template launch<Kernel<true, false>>(blocks, kCompositeBlock, args);
  } else {
    if (fused)
      backend.template launch<Kernel<false, true>>(blocks, kCompositeBlock, args);
    else
      backend.template launch<Kernel<false, false>>(blocks, kCompositeBlock, args);
  }
}

template <class Backend>
class StagePipeline final : public StageRunner {
public:
  template <class... A>
  explicit StagePipeline(const char* name, A&&... backend_args)
      : name_(name), backend_(std::forward<A>(backend_args)...) {}

  const char* name() const override { return name_; }

  const ForwardStages& forward(const cpu::ModelView<float>& model, const float* opacity_multiplier,
                               const CameraParams<float>& camera, const StageOptions& options) override {
    begin_forward(model.count, model.sh_degree, opacity_multiplier != nullptr, camera, options);
    const UploadedModel uploaded{model.means, model.log_scales, model.quats, model.opacity_logits, model.sh_dc,
                                 model.sh_rest, opacity_multiplier, n_, rest_count_};
    if (!timing_ || !(uploaded == uploaded_)) {
      backend_.upload(means_, model.means, n_ * 3);
      backend_.upload(log_scales_, model.log_scales, n_ * 3);
      backend_.upload(quats_, model.quats, n_ * 4);
      backend_.upload(opacity_logits_, model.opacity_logits, n_);
      backend_.upload(sh_dc_, model.sh_dc, n_ * 3);
      backend_.upload(sh_rest_, model.sh_rest, n_ * static_cast<std::size_t>(rest_count_) * 3);
      if (has_multiplier_) backend_.upload(multiplier_, opacity_multiplier, n_);
      uploaded_ = uploaded;
    }
    launch_forward();

    auto& out = out_;
    const std::size_t ms = static_cast<std::size_t>(intersections_);
    const int tiles = out.tiles_x * out.tiles_y;
    copy_out(out.mean2d, mean2d_, n_ * 2);
    copy_out(out.conic, conic_, n_ * 3);
    copy_out(out.depth, depth_, n_);
    copy_out(out.opacity, opacity_, n_);
    copy_out(out.radii, radii_, n_);
    copy_out(out.color, color_, n_ * 3);
    copy_out(out.color_clamped, clamped_, n_ * 3);
    copy_out(out.rects, rects_, n_ * 4);
    copy_out(out.tile_counts, counts_, n_);
    copy_out(out.isect_offsets, offsets_, n_);
    copy_out(out.isect_keys, keys_sorted_, ms);
    copy_out(out.isect_gaussians, gaussians_sorted_, ms);
    copy_out(out.tile_ranges, ranges_, static_cast<std::size_t>(tiles) * 2);
    return out_;
  }

  const BackwardStages& backward(const ProjectedGradsIn& g) override {
    if (!has_model_) fail("stages: backward() needs a forward() first");
    backend_.upload(d_mean2d_, g.mean2d, n_ * 2);
    backend_.upload(d_conic_, g.conic, n_ * 3);
    backend_.upload(d_depth_, g.depth, n_);
    backend_.upload(d_opacity_, g.opacity, n_);
    backend_.upload(d_color_, g.color, n_ * 3);
    composite_grads_ = false;
    return model_backward();
  }

  const BackwardStages& backward_from_composite() override {
    if (!has_model_ || !composite_grads_)
      fail("stages: backward_from_composite() needs forward(), composite() and composite_backward() first");
    return model_backward();
  }

  void load_projected(const ProjectedIn& in) override {
    if (in.width <= 0 || in.height <= 0) fail("stages: image size {}x{} is empty", in.width, in.height);
    if (in.n > static_cast<std::size_t>(1) << 30) fail("stages: {} Gaussians exceed the int32 indices", in.n);
    n_ = in.n;
    has_model_ = composited_ = composite_grads_ = false;
    camera_.width = in.width;
    camera_.height = in.height;
    out_.tiles_x = (in.width + kTileSize - 1) / kTileSize;
    out_.tiles_y = (in.height + kTileSize - 1) / kTileSize;
    const std::size_t tiles = static_cast<std::size_t>(out_.tiles_x) * out_.tiles_y;
    backend_.upload(mean2d_, in.mean2d, n_ * 2);
    backend_.upload(conic_, in.conic, n_ * 3);
    backend_.upload(depth_, in.depth, n_);
    backend_.upload(opacity_, in.opacity, n_);
    backend_.upload(color_, in.color, n_ * 3);
    backend_.upload(gaussians_sorted_, in.isect_gaussians, in.intersections);
    backend_.upload(ranges_, in.tile_ranges, tiles * 2);
  }

  const CompositeStages& composite(const CompositeOptions& options) override {
    const int width = camera_.width, height = camera_.height;
    if (width <= 0 || height <= 0) fail("stages: composite() needs forward() or load_projected() first");
    composite_options_ = options;
    launch_composite_forward();
    const std::size_t pixels = static_cast<std::size_t>(width) * height;
    copy_out(composite_out_.rgb, rgb_, pixels * 3);
    copy_out(composite_out_.alpha, alpha_, pixels);
    copy_out(composite_out_.depth, pixel_depth_, pixels);
    copy_out(composite_out_.final_transmittance, final_t_, pixels);
    copy_out(composite_out_.n_contrib, n_contrib_, pixels);
    return composite_out_;
  }

  const CompositeGrads& composite_backward(const float* d_rgb, const float* d_alpha, const float* d_depth) override {
    if (!composited_) fail("stages: composite_backward() needs composite() first");
    const int width = camera_.width, height = camera_.height;
    const std::size_t pixels = static_cast<std::size_t>(width) * height;
    if (d_rgb) backend_.upload(d_rgb_, d_rgb, pixels * 3);
    if (d_alpha) backend_.upload(d_alpha_, d_alpha, pixels);
    if (d_depth) backend_.upload(d_pixel_depth_, d_depth, pixels);
    launch_composite_backward(d_rgb != nullptr, d_alpha != nullptr, d_depth != nullptr);
    copy_out(composite_grads_out_.mean2d, d_mean2d_, n_ * 2);
    copy_out(composite_grads_out_.conic, d_conic_, n_ * 3);
    copy_out(composite_grads_out_.depth, d_depth_, n_);
    copy_out(composite_grads_out_.opacity, d_opacity_, n_);
    copy_out(composite_grads_out_.color, d_color_, n_ * 3);
    return composite_grads_out_;
  }

private:
  // What the compositing forward and backward read alike (CompositeFwdArgs, CompositeBwdArgs): the image
  // and its tiles, the projected Gaussians, their sorted intersections and composite()'s background.
  template <class Args>
  Args composite_args() {
    Args c;
    c.width = camera_.width;
    c.height = camera_.height;
    c.tiles_x = out_.tiles_x;
    c.mean2d = mean2d_.data();
    c.conic = conic_.data();
    c.opacity = opacity_.data();
    c.color = color_.data();
    c.depth = depth_.data();
    c.isect_gaussians = gaussians_sorted_.data();
    c.tile_ranges = ranges_.data();
    for (int k = 0; k < 3; ++k) c.background[k] = composite_options_.background[k];
    return c;
  }

  // The checks and the state of a forward (host or resident) of n Gaussians of SH degree sh_degree.
  void begin_forward(std::size_t n, int sh_degree, bool with_multiplier, const CameraParams<float>& camera,
                     const StageOptions& options) {
    if (sh_degree < 0 || sh_degree > 3) fail("stages: model SH degree {} is outside 0..3", sh_degree);
    if (options.active_degree < 0 || options.active_degree > sh_degree)
      fail("stages: active SH degree {} is outside 0..{}", options.active_degree, sh_degree);
    if (camera.width <= 0 || camera.height <= 0) fail("stages: camera size {}x{} is empty", camera.width, camera.height);
    if (n > static_cast<std::size_t>(1) << 30) fail("stages: {} Gaussians exceed the int32 indices", n);
    n_ = n;
    rest_count_ = (sh_degree + 1) * (sh_degree + 1) - 1;
    has_model_ = true;
    composited_ = composite_grads_ = false;
    camera_ = camera;
    options_ = options;
    has_multiplier_ = with_multiplier;
  }

  // The launches of forward(): projection, SH, tile intersection of the n_ Gaussians in means_ ... with
  // camera_ and options_; the one value read back is the number of intersections.
  void launch_forward() {
    const int n = static_cast<int>(n_);
    mean2d_.resize(n_ * 2);
    conic_.resize(n_ * 3);
    depth_.resize(n_);
    opacity_.resize(n_);
    radii_.resize(n_);
    color_.resize(n_ * 3);
    clamped_.resize(n_ * 3);
    rects_.resize(n_ * 4);
    counts_.resize(n_);
    offsets_.resize(n_);

    auto& out = out_;
    out.tiles_x = (camera_.width + kTileSize - 1) / kTileSize;
    out.tiles_y = (camera_.height + kTileSize - 1) / kTileSize;
    const int tiles = out.tiles_x * out.tiles_y;
    const int blocks = blocks_for(n);

    ProjectionFwdArgs p;
    p.n = n;
    p.tiles_x = out.tiles_x;
    p.tiles_y = out.tiles_y;
    p.means = means_.data();
    p.log_scales = log_scales_.data();
    p.quats = quats_.data();
    p.opacity_logits = opacity_logits_.data();
    p.multiplier = has_multiplier_ ? multiplier_.data() : nullptr;
    p.cam = camera_;
    p.mean2d = mean2d_.data();
    p.conic = conic_.data();
    p.depth = depth_.data();
    p.opacity = opacity_.data();
    p.radii = radii_.data();
    backend_.template launch<ProjectionFwdKernel>(blocks, kBlockThreads, p);

    ShFwdArgs s;
    s.n = n;
    s.active_degree = options_.active_degree;
    s.rest_count = rest_count_;
    s.means = means_.data();
    s.sh_dc = sh_dc_.data();
    s.sh_rest = sh_rest_.data();
    s.radii = radii_.data();
    for (int k = 0; k < 3; ++k) s.campos[k] = camera_.campos[k];
    s.color = color_.data();
    s.color_clamped = clamped_.data();
    backend_.template launch<ShFwdKernel>(blocks, kBlockThreads, s);

    TileCountArgs c;
    c.n = n;
    c.tiles_x = out.tiles_x;
    c.tiles_y = out.tiles_y;
    c.height = camera_.height;
    c.alpha_min = static_cast<float>(options_.alpha_min);
    c.mean2d = mean2d_.data();
    c.conic = conic_.data();
    c.opacity = opacity_.data();
    c.radii = radii_.data();
    c.rects = rects_.data();
    c.counts = counts_.data();
    c.offsets = offsets_.data();
    backend_.template launch<TileCountKernel>(blocks, kBlockThreads, c);
    // The int scan could overflow only where every Gaussian covering every tile would: there the counts
    // are summed on the host first (a frame that needs more pairs than the tile lists can index is refused).
    if (static_cast<std::int64_t>(n_) * tiles > cpu::kMaxIntersections) {
      std::vector<int> counts;
      backend_.download(counts, counts_, n_);
      std::int64_t total = 0;
      for (int k : counts) total += k;
      cpu::check_intersection_count(total, camera_.width, camera_.height);
    }
    kernels::inclusive_scan(backend_, offsets_.data(), n, scan_levels_);

    const int m = n > 0 ? backend_.read(offsets_, n_ - 1) : 0;  // the one value read back
    intersections_ = m;
    const std::size_t ms = static_cast<std::size_t>(m);
    keys_.resize(ms);
    keys_sorted_.resize(ms);
    gaussians_.resize(ms);
    gaussians_sorted_.resize(ms);
    ranges_.resize(static_cast<std::size_t>(tiles) * 2);
    EmitKeysArgs e;
    e.n = n;
    e.tiles = c;
    e.offsets = offsets_.data();
    e.depth = depth_.data();
    e.keys = keys_.data();
    e.gaussians = gaussians_.data();
    backend_.template launch<EmitKeysKernel>(blocks, kBlockThreads, e);
    backend_.sort_pairs(keys_, keys_sorted_, gaussians_, gaussians_sorted_, ms, 32 + tile_id_bits(tiles));
    backend_.zero(ranges_, static_cast<std::size_t>(tiles) * 2);
    TileRangesArgs r;
    r.m = m;
    r.keys = keys_sorted_.data();
    r.ranges = ranges_.data();
    backend_.template launch<TileRangesKernel>(blocks_for(m), kBlockThreads, r);
  }

  // The launch of composite(): the image of the projected Gaussians with composite_options_.
  void launch_composite_forward() {
    const std::size_t pixels = static_cast<std::size_t>(camera_.width) * camera_.height;
    rgb_.resize(pixels * 3);
    alpha_.resize(pixels);
    pixel_depth_.resize(pixels);
    final_t_.resize(pixels);
    n_contrib_.resize(pixels);
    auto c = composite_args<CompositeFwdArgs>();
    c.rgb = rgb_.data();
    c.alpha = alpha_.data();
    c.out_depth = pixel_depth_.data();
    c.final_t = final_t_.data();
    c.n_contrib = n_contrib_.data();
    launch_composite<CompositeFwdKernel>(backend_, out_.tiles_x * out_.tiles_y, c, composite_options_.smooth_cutoff,
                                         composite_options_.fused_multiply_add);
    composited_ = true;
    composite_grads_ = false;
  }

  // The launch of composite_backward() from the image gradients in d_rgb_, d_alpha_, d_pixel_depth_ (those
  // flagged; the others zero), into d_mean2d_ ... d_color_.
  void launch_composite_backward(bool has_rgb, bool has_alpha, bool has_depth) {
    d_mean2d_.resize(n_ * 2);
    d_conic_.resize(n_ * 3);
    d_depth_.resize(n_);
    d_opacity_.resize(n_);
    d_color_.resize(n_ * 3);
    backend_.zero(d_mean2d_, n_ * 2);
    backend_.zero(d_conic_, n_ * 3);
    backend_.zero(d_depth_, n_);
    backend_.zero(d_opacity_, n_);
    backend_.zero(d_color_, n_ * 3);
    auto c = composite_args<CompositeBwdArgs>();
    c.clamp_pass_through = composite_options_.clamp_pass_through;
    c.final_t = final_t_.data();
    c.n_contrib = n_contrib_.data();
    c.d_rgb = has_rgb ? d_rgb_.data() : nullptr;
    c.d_alpha = has_alpha ? d_alpha_.data() : nullptr;
    c.d_depth = has_depth ? d_pixel_depth_.data() : nullptr;
    c.d_mean2d = d_mean2d_.data();
    c.d_conic = d_conic_.data();
    c.d_opacity = d_opacity_.data();
    c.d_color = d_color_.data();
    c.d_splat_depth = d_depth_.data();
    launch_composite<CompositeBwdKernel>(backend_, out_.tiles_x * out_.tiles_y, c, composite_options_.smooth_cutoff,
                                         composite_options_.fused_multiply_add);
    composite_grads_ = true;
  }

  // The launches of model_backward(): d_means_ ... d_sh_rest_ from d_mean2d_ ... d_color_.
  void launch_model_backward() {
    const int n = static_cast<int>(n_);
    const std::size_t rest = n_ * static_cast<std::size_t>(rest_count_) * 3;
    d_means_.resize(n_ * 3);
    d_log_scales_.resize(n_ * 3);
    d_quats_.resize(n_ * 4);
    d_opacity_logits_.resize(n_);
    d_sh_dc_.resize(n_ * 3);
    d_sh_rest_.resize(rest);
    const int blocks = blocks_for(n);

    ProjectionBwdArgs p;
    p.n = n;
    p.means = means_.data();
    p.log_scales = log_scales_.data();
    p.quats = quats_.data();
    p.opacity_logits = opacity_logits_.data();
    p.multiplier = has_multiplier_ ? multiplier_.data() : nullptr;
    p.cam = camera_;
    p.radii = radii_.data();
    p.d_mean2d = d_mean2d_.data();
    p.d_conic = d_conic_.data();
    p.d_depth = d_depth_.data();
    p.d_opacity = d_opacity_.data();
    p.d_means = d_means_.data();
    p.d_log_scales = d_log_scales_.data();
    p.d_quats = d_quats_.data();
    p.d_opacity_logits = d_opacity_logits_.data();
    backend_.template launch<ProjectionBwdKernel>(blocks, kBlockThreads, p);

    ShBwdArgs s;
    s.n = n;
    s.active_degree = options_.active_degree;
    s.rest_count = rest_count_;
    s.means = means_.data();
    s.sh_dc = sh_dc_.data();
    s.sh_rest = sh_rest_.data();
    s.radii = radii_.data();
    s.color_clamped = clamped_.data();
    for (int k = 0; k < 3; ++k) s.campos[k] = camera_.campos[k];
    s.d_color = d_color_.data();
    s.d_sh_dc = d_sh_dc_.data();
    s.d_sh_rest = d_sh_rest_.data();
    s.d_means = d_means_.data();
    backend_.template launch<ShBwdKernel>(blocks, kBlockThreads, s);
  }

  // Projection and SH backward from the projected gradients in d_mean2d_ ... d_color_.
  const BackwardStages& model_backward() {
    launch_model_backward();
    const std::size_t rest = n_ * static_cast<std::size_t>(rest_count_) * 3;
    copy_out(grads_.means, d_means_, n_ * 3);
    copy_out(grads_.log_scales, d_log_scales_, n_ * 3);
    copy_out(grads_.quats, d_quats_, n_ * 4);
    copy_out(grads_.opacity_logits, d_opacity_logits_, n_);
    copy_out(grads_.sh_dc, d_sh_dc_, n_ * 3);
    copy_out(grads_.sh_rest, d_sh_rest_, rest);
    return grads_;
  }

public:
  void set_timing_mode(bool on) override {
    timing_ = on;
    uploaded_ = UploadedModel{};
  }
  void synchronize() override { backend_.synchronize(); }

  // ---- Device-resident use, by code that knows the Backend (train/kernels/resident_step.hpp) ----
  // The model lives in the pipeline's own arrays (model()), written there by the caller (an upload, Adam's
  // kernel, a densification); forward_resident(), composite_resident() and backward_resident() run the
  // launches of forward(), composite() and composite_backward() + backward_from_composite() without an
  // upload or a copy to the host. The caller writes the image gradients into image_gradients() between
  // composite_resident() and backward_resident().
  template <class T>
  using Array = typename Backend::template Array<T>;
  struct ModelArrays {
    Array<float>&means, &log_scales, &quats, &opacity_logits, &sh_dc, &sh_rest;
  };
  struct ImageArrays {
    Array<float>&rgb, &alpha, &depth;  // H x W x 3, H x W, H x W
  };

  Backend& backend() { return backend_; }
  ModelArrays model() { return {means_, log_scales_, quats_, opacity_logits_, sh_dc_, sh_rest_}; }
  // The opacity multiplier of the next forward_resident(..., true) (n values).
  Array<float>& multiplier() { return multiplier_; }
  // d loss / d model of the last backward_resident().
  ModelArrays gradients() {
    return {d_means_, d_log_scales_, d_quats_, d_opacity_logits_, d_sh_dc_, d_sh_rest_};
  }
  ImageArrays image() { return {rgb_, alpha_, pixel_depth_}; }
  ImageArrays image_gradients() { return {d_rgb_, d_alpha_, d_pixel_depth_}; }
  Array<int>& radii() { return radii_; }
  // d loss / d mean2d in pixels (n x 2) of the last backward_resident().
  Array<float>& mean2d_gradient() { return d_mean2d_; }
  int intersections() const { return intersections_; }

  void forward_resident(std::size_t n, int sh_degree, bool with_multiplier, const CameraParams<float>& camera,
                        const StageOptions& options) {
    begin_forward(n, sh_degree, with_multiplier, camera, options);
    uploaded_ = UploadedModel{};  // the arrays no longer hold an upload of timing mode's
    launch_forward();
  }
  void composite_resident(const CompositeOptions& options) {
    if (!has_model_) fail("stages: composite_resident() needs forward_resident() first");
    composite_options_ = options;
    launch_composite_forward();
    const std::size_t pixels = static_cast<std::size_t>(camera_.width) * camera_.height;
    d_rgb_.resize(pixels * 3);
    d_alpha_.resize(pixels);
    d_pixel_depth_.resize(pixels);
  }
  void backward_resident(bool with_alpha, bool with_depth) {
    if (!composited_) fail("stages: backward_resident() needs composite_resident() first");
    launch_composite_backward(true, with_alpha, with_depth);
    launch_model_backward();
  }

  std::vector<int> inclusive_scan(const std::vector<int>& values) override {
    backend_.upload(scan_data_, values.data(), values.size());
    kernels::inclusive_scan(backend_, scan_data_.data(), static_cast<int>(values.size()), scan_levels_);
    std::vector<int> out;
    backend_.download(out, scan_data_, values.size());
    return out;
  }

private:
  // An output's copy to the host, skipped in timing mode.
  template <class T>
  void copy_out(std::vector<T>& dst, const Array<T>& src, std::size_t n) {
    if (!timing_) backend_.download(dst, src, n);
  }
  // Which host arrays the device copy of the model came from (timing mode's test for a re-upload).
  struct UploadedModel {
    const float *means = nullptr, *log_scales = nullptr, *quats = nullptr, *opacity_logits = nullptr,
                *sh_dc = nullptr, *sh_rest = nullptr, *multiplier = nullptr;
    std::size_t n = 0;
    int rest_count = -1;
    bool operator==(const UploadedModel& o) const {  // C++17: nvcc compiles this header
      return means == o.means && log_scales == o.log_scales && quats == o.quats && opacity_logits == o.opacity_logits &&
             sh_dc == o.sh_dc && sh_rest == o.sh_rest && multiplier == o.multiplier && n == o.n &&
             rest_count == o.rest_count;
    }
  };

  const char* name_;
  Backend backend_;
  std::size_t n_ = 0;
  int rest_count_ = 0;
  bool has_multiplier_ = false;
  bool has_model_ = false;        // forward() ran (not load_projected())
  bool composited_ = false;       // composite() ran on the current Gaussians
  bool composite_grads_ = false;  // composite_backward() left gradients in d_mean2d_ ...
  bool timing_ = false;           // set_timing_mode()
  UploadedModel uploaded_{};      // in timing mode: the arrays of the model now on the device
  CompositeOptions composite_options_{};
  CameraParams<float> camera_{};
  StageOptions options_{};
  Array<float> means_, log_scales_, quats_, opacity_logits_, multiplier_, sh_dc_, sh_rest_;
  Array<float> mean2d_, conic_, depth_, opacity_, color_;
  Array<int> radii_, rects_, counts_, offsets_, ranges_, scan_data_;
  Array<std::uint8_t> clamped_;
  std::vector<Array<int>> scan_levels_;
  Array<std::uint64_t> keys_, keys_sorted_;
  Array<std::int32_t> gaussians_, gaussians_sorted_;
  Array<float> d_mean2d_, d_conic_, d_depth_, d_opacity_, d_color_;
  Array<float> d_means_, d_log_scales_, d_quats_, d_opacity_logits_, d_sh_dc_, d_sh_rest_;
  Array<float> rgb_, alpha_, pixel_depth_, final_t_, d_rgb_, d_alpha_, d_pixel_depth_;
  Array<int> n_contrib_;
  int intersections_ = 0;  // of the last forward
  ForwardStages out_;
  BackwardStages grads_;
  CompositeStages composite_out_;
  CompositeGrads composite_grads_out_;
};

}  // namespace d2gs::render::kernels
