#pragma once
// The host side of the SSIM kernels (ssim_kernels.hpp) over a backend of render/kernels/pipeline.hpp:
// the launch sequence of Ssim<float>::reference and Ssim<float>::evaluate, written once, run by CI through
// the emulator. Host arrays in and out (the trainer's device path will keep them on the device).
#include <algorithm>
#include <vector>

#include "d2gs/core/error.hpp"
#include "d2gs/eval/ssim.hpp"
#include "d2gs/render/kernels/block.hpp"
#include "d2gs/train/kernels/ssim_kernels.hpp"

namespace d2gs::train_kernels {

template <class Backend>
class SsimPipeline {
public:
  explicit SsimPipeline(Backend& backend) : backend_(backend) {}

  // Ssim<float>::reference(b, width, height, channels).
  Ssim<float>::Reference reference(const float* b, int width, int height, int channels) {
    check_size(width, height, channels);
    const int n = width * height * channels;
    backend_.upload(a_, b, static_cast<std::size_t>(n));
    planes_.resize(2 * static_cast<std::size_t>(n));
    SsimReferencePlanesArgs p;
    p.n = n;
    p.pixels = width * height;
    p.channels = channels;
    p.b = a_.data();
    p.planes = planes_.data();
    render::kernels::launch_per_item<SsimReferencePlanesKernel>(backend_, n, p);
    blur(planes_, 2 * n, width, height, blurred_);  // mu_b (C planes), s_bb (C planes)
    Ssim<float>::Reference ref;
    ref.width = width;
    ref.height = height;
    ref.channels = channels;
    backend_.download(ref.b, planes_, static_cast<std::size_t>(n));
    std::vector<float> stats;
    backend_.download(stats, blurred_, 2 * static_cast<std::size_t>(n));
    ref.mu_b.assign(stats.begin(), stats.begin() + n);
    ref.s_bb.assign(stats.begin() + n, stats.end());
    return ref;
  }

  // Ssim<float>::evaluate(a, ref, grad, grad_scale): the mean SSIM (in double, before the CPU's rounding of
  // it to float); grad_scale · d(mean SSIM)/da is ADDED to grad (if non-null), which holds the other loss
  // terms' gradients (the L1 gradient in the training step), as the CPU's Ssim::evaluate adds.
  double evaluate(const float* a, const Ssim<float>::Reference& ref, float* grad, float grad_scale) {
    const int width = ref.width, height = ref.height, channels = ref.channels;
    check_size(width, height, channels);
    const std::size_t values = static_cast<std::size_t>(width) * height * channels;
    if (ref.b.size() != values || ref.mu_b.size() != values || ref.s_bb.size() != values)
      fail("SSIM kernels: invalid reference image");
    backend_.upload(a_, a, values);
    backend_.upload(b_, ref.b.data(), values);
    backend_.upload(mu_b_, ref.mu_b.data(), values);
    backend_.upload(s_bb_, ref.s_bb.data(), values);
    if (grad) backend_.upload(grad_, grad, values);  // the gradient so far, which the kernel adds to
    const double mean = evaluate_on(a_.data(), b_.data(), mu_b_.data(), s_bb_.data(), width, height, channels,
                                    grad ? grad_.data() : nullptr, grad_scale);
    if (grad) {
      std::vector<float> out;
      backend_.download(out, grad_, values);
      std::copy(out.begin(), out.end(), grad);
    }
    return mean;
  }

  // The same on arrays of the backend: a (the prediction, interleaved), the reference's planes b, mu_b, s_bb
  // (Reference's layout) and grad (if non-null, interleaved), which the gradient is added to.
  double evaluate_on(const float* a, const float* b, const float* mu_b, const float* s_bb, int width, int height,
                     int channels, float* grad, float grad_scale) {
    check_size(width, height, channels);
    const std::size_t values = static_cast<std::size_t>(width) * height * channels;
    const int n = static_cast<int>(values);

    // The blurs' inputs a, a², a·b, and their local means mu_a, s_aa, s_ab (C planes each).
    planes_.resize(3 * values);
    SsimPlanesArgs p;
    p.n = n;
    p.pixels = width * height;
    p.channels = channels;
    p.a = a;
    p.b = b;
    p.planes = planes_.data();
    render::kernels::launch_per_item<SsimPlanesKernel>(backend_, n, p);
    blur(planes_, 3 * n, width, height, blurred_);

    // The map, its sum per block, its local derivatives; the partial sums added in a fixed order.
    const double inv_count = 1.0 / (static_cast<double>(width) * height * channels);
    const int blocks = render::kernels::blocks_for(n);
    partials_.resize(static_cast<std::size_t>(blocks));
    sum_.resize(1);
    SsimMapArgs m;
    m.n = n;
    m.mu_a = blurred_.data();
    m.s_aa = blurred_.data() + values;
    m.s_ab = blurred_.data() + 2 * values;
    m.mu_b = mu_b;
    m.s_bb = s_bb;
    m.c1 = static_cast<float>(kSsimC1);
    m.c2 = static_cast<float>(kSsimC2);
    m.g = grad_scale * static_cast<float>(inv_count);
    if (grad) {  // d_mu, d_saa, d_sab (C planes each) into planes_, free again
      m.d_mu = planes_.data();
      m.d_saa = planes_.data() + values;
      m.d_sab = planes_.data() + 2 * values;
    }
    m.partials = partials_.data();
    backend_.template launch<SsimMapKernel>(blocks, render::kernels::kBlockThreads, m);
    SumPartialsArgs s;
    s.n = blocks;
    s.partials = partials_.data();
    s.sum = sum_.data();
    backend_.template launch<SumPartialsKernel>(1, render::kernels::kBlockThreads, s);

    if (grad) {
      blur(planes_, 3 * n, width, height, blurred_);  // blurred_ (mu_a, s_aa, s_ab) is no longer needed
      SsimGradArgs g;
      g.n = n;
      g.pixels = width * height;
      g.channels = channels;
      g.a = a;
      g.b = b;
      g.blurred_d_mu = blurred_.data();
      g.blurred_d_saa = blurred_.data() + values;
      g.blurred_d_sab = blurred_.data() + 2 * values;
      g.grad = grad;
      render::kernels::launch_per_item<SsimGradKernel>(backend_, n, g);
    }
    return backend_.read(sum_, 0) * inv_count;
  }

private:
  template <class T>
  using Array = typename Backend::template Array<T>;

  static void check_size(int width, int height, int channels) {
    if (width <= 0 || height <= 0 || channels <= 0)
      fail("SSIM kernels: invalid image size {}x{}x{}", width, height, channels);
    if (static_cast<long long>(width) * height * channels * 3 > (1LL << 31) - 1)
      fail("SSIM kernels: {}x{}x{} values exceed the int32 indices", width, height, channels);
  }
  // The separable blur of `count` values (whole planes of width x height) in `in` into `out` (rows into
  // tmp_, then columns).
  void blur(Array<float>& in, int count, int width, int height, Array<float>& out) {
    static const auto w = ssim_window<float>();
    tmp_.resize(static_cast<std::size_t>(count));
    out.resize(static_cast<std::size_t>(count));
    BlurArgs rows;
    rows.n = count;
    rows.width = width;
    rows.height = height;
    std::copy(w.begin(), w.end(), rows.w);
    BlurArgs columns = rows;
    rows.in = in.data();
    rows.out = tmp_.data();
    render::kernels::launch_per_item<BlurRowsKernel>(backend_, count, rows);
    columns.in = tmp_.data();
    columns.out = out.data();
    render::kernels::launch_per_item<BlurColumnsKernel>(backend_, count, columns);
  }

  Backend& backend_;
  Array<float> a_, b_, mu_b_, s_bb_, planes_, tmp_, blurred_, grad_;
  Array<double> partials_, sum_;
};

}  // namespace d2gs::train_kernels
