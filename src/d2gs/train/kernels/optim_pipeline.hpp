#pragma once
// The host side of the Adam, L1 and DAFE kernels over a backend of render/kernels/pipeline.hpp (host vectors and
// the emulator, or device memory and kernel_shell): written once, run by CI through the emulator.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "d2gs/core/error.hpp"
#include "d2gs/render/kernels/block.hpp"
#include "d2gs/train/adam.hpp"
#include "d2gs/train/kernels/adam_kernels.hpp"
#include "d2gs/train/kernels/dafe_kernels.hpp"
#include "d2gs/train/kernels/l1_kernels.hpp"
#include "d2gs/train/losses.hpp"

namespace d2gs::train_kernels {

// Adam::step's scalars of a group with learning rate lr (bias1, bias2 of the step).
inline AdamScalars adam_scalars(double lr, double bias1, double bias2) {
  AdamScalars s;
  s.b1 = static_cast<float>(Adam::kBeta1);
  s.b2 = static_cast<float>(Adam::kBeta2);
  s.step_size = static_cast<float>(lr / bias1);
  s.inv_sqrt_bias2 = static_cast<float>(1.0 / std::sqrt(bias2));
  s.eps = static_cast<float>(Adam::kEps);
  return s;
}

// One parameter group's update in the backend's memory: n values of param, grad and the moments.
template <class Backend>
void adam_group(Backend& backend, float* param, const float* grad, float* exp_avg, float* exp_avg_sq, std::size_t n,
                const AdamScalars& scalars) {
  if (n == 0) return;
  AdamArgs a;
  a.n = static_cast<int>(n);
  a.param = param;
  a.grad = grad;
  a.exp_avg = exp_avg;
  a.exp_avg_sq = exp_avg_sq;
  a.s = scalars;
  render::kernels::launch_per_item<AdamKernel>(backend, static_cast<long long>(n), a);
}

template <class Backend>
void adam_step(Backend& backend, Gaussians& model, const Gaussians& grads, AdamState& state, const LearningRates& lr,
               float means_lr, bool skip_opacity) {
  grads.validate();
  if (grads.size() != model.size() || state.exp_avg.size() != model.size() || grads.sh_degree != model.sh_degree)
    fail("Adam: model, gradients and moments are not aligned ({}, {}, {} rows)", model.size(), grads.size(),
         state.exp_avg.size());
  ++state.step;
  const double bias1 = 1.0 - std::pow(Adam::kBeta1, static_cast<double>(state.step));
  const double bias2 = 1.0 - std::pow(Adam::kBeta2, static_cast<double>(state.step));
  typename Backend::template Array<float> p, g, m, v;
  auto group = [&](std::vector<float>& param, const std::vector<float>& grad, std::vector<float>& exp_avg,
                   std::vector<float>& exp_avg_sq, double rate) {
    const std::size_t n = param.size();
    if (n == 0) return;
    backend.upload(p, param.data(), n);
    backend.upload(g, grad.data(), n);
    backend.upload(m, exp_avg.data(), n);
    backend.upload(v, exp_avg_sq.data(), n);
    adam_group(backend, p.data(), g.data(), m.data(), v.data(), n, adam_scalars(rate, bias1, bias2));
    backend.download(param, p, n);
    backend.download(exp_avg, m, n);
    backend.download(exp_avg_sq, v, n);
  };
  auto& em = state.exp_avg;
  auto& ev = state.exp_avg_sq;
  group(model.means, grads.means, em.means, ev.means, means_lr);
  group(model.sh_dc, grads.sh_dc, em.sh_dc, ev.sh_dc, lr.sh_dc);
  group(model.sh_rest, grads.sh_rest, em.sh_rest, ev.sh_rest, lr.sh_rest);
  if (!skip_opacity) group(model.opacity_logits, grads.opacity_logits, em.opacity_logits, ev.opacity_logits, lr.opacity);
  group(model.log_scales, grads.log_scales, em.log_scales, ev.log_scales, lr.scales);
  group(model.quats, grads.quats, em.quats, ev.quats, lr.quats);
}

// The L1 kernel on arrays of the backend: grad (if non-null) += scale/count · sign(a − b); `sum` (one double,
// set here) receives the sum of |a − b| for the caller to read.
template <class Backend>
void l1_loss_launch(Backend& backend, const float* a, const float* b, std::size_t count, float* grad, float scale,
                    typename Backend::template Array<double>& sum) {
  sum.resize(1);
  backend.zero(sum, 1);
  L1Args args;
  args.n = static_cast<int>(count);
  args.a = a;
  args.b = b;
  args.grad = grad;
  args.g = scale / static_cast<float>(count);
  args.sum = sum.data();
  render::kernels::launch_per_item<L1Kernel>(backend, static_cast<long long>(count), args);
}

template <class Backend>
double l1_loss(Backend& backend, const float* a, const float* b, std::size_t count, float* grad, float scale) {
  if (count == 0) return 0.0;
  if (count > (std::size_t{1} << 31) - 1) fail("L1 kernel: {} values exceed the int32 indices", count);
  typename Backend::template Array<float> da, db, dg;
  typename Backend::template Array<double> sum;
  backend.upload(da, a, count);
  backend.upload(db, b, count);
  if (grad) backend.upload(dg, grad, count);
  l1_loss_launch(backend, da.data(), db.data(), count, grad ? dg.data() : nullptr, scale, sum);
  if (grad) {
    std::vector<float> out;
    backend.download(out, dg, count);
    std::copy(out.begin(), out.end(), grad);
  }
  return backend.read(sum, 0) / static_cast<double>(count);
}

// What the DAFE kernels keep in the backend's memory: the per-block partial sums and the totals.
template <class Backend>
struct DafeBuffers {
  typename Backend::template Array<double> sums, masked;
  typename Backend::template Array<DafeTotals> totals;
};

// The DAFE kernels on arrays of the backend: a and b (H x W x C, interleaved), the H x W mask, grad (if
// non-null: += scale · d/da on the masked values); returns the loss (one value read back).
template <class Backend>
double dafe_loss_launch(Backend& backend, DafeBuffers<Backend>& buffers, const float* a, const float* b,
                        const std::uint8_t* mask, int width, int height, int channels, DafeLossForm form, float* grad,
                        float scale) {
  const std::size_t pixels = static_cast<std::size_t>(width) * height;
  const std::size_t values = pixels * static_cast<std::size_t>(channels);
  if (values > (std::size_t{1} << 31) - 1) fail("DAFE kernels: {} values exceed the int32 indices", values);
  const int n = static_cast<int>(values);
  const int blocks = render::kernels::blocks_for(n);
  buffers.sums.resize(static_cast<std::size_t>(blocks));
  buffers.masked.resize(static_cast<std::size_t>(blocks));
  buffers.totals.resize(1);
  DafeSumArgs s;
  s.n = n;
  s.channels = channels;
  s.a = a;
  s.b = b;
  s.mask = mask;
  s.partial_sums = buffers.sums.data();
  s.partial_masked = buffers.masked.data();
  backend.template launch<DafeSumKernel>(blocks, render::kernels::kBlockThreads, s);
  DafeTotalArgs t;
  t.blocks = blocks;
  t.partial_sums = buffers.sums.data();
  t.partial_masked = buffers.masked.data();
  t.values = static_cast<double>(pixels) * channels;
  t.paper_form = form == DafeLossForm::Paper;
  t.scale = scale;
  t.totals = buffers.totals.data();
  backend.template launch<DafeTotalKernel>(1, render::kernels::kBlockThreads, t);
  if (grad) {
    DafeGradArgs g;
    g.n = n;
    g.channels = channels;
    g.a = a;
    g.b = b;
    g.mask = mask;
    g.totals = buffers.totals.data();
    g.grad = grad;
    backend.template launch<DafeGradKernel>(blocks, render::kernels::kBlockThreads, g);
  }
  return backend.read(buffers.totals, 0).loss;
}

// dafe_loss(a, b, width, height, channels, mask, form, grad, scale): the value (a fixed-order double sum)
// and grad += scale · d/da on the masked values.
template <class Backend>
double dafe_loss(Backend& backend, const float* a, const float* b, int width, int height, int channels,
                 const std::vector<std::uint8_t>& mask, DafeLossForm form, float* grad, float scale) {
  const std::size_t pixels = static_cast<std::size_t>(width) * height;
  if (mask.size() != pixels) fail("DAFE: mask has {} pixels, image {}x{}", mask.size(), width, height);
  if (width <= 0 || height <= 0 || channels <= 0) return 0.0;  // no pixels: the CPU's denominator is 0
  const std::size_t values = pixels * static_cast<std::size_t>(channels);
  if (values > (std::size_t{1} << 31) - 1) fail("DAFE kernels: {} values exceed the int32 indices", values);
  typename Backend::template Array<float> da, db, dg;
  typename Backend::template Array<std::uint8_t> dm;
  DafeBuffers<Backend> buffers;
  backend.upload(da, a, values);
  backend.upload(db, b, values);
  backend.upload(dm, mask.data(), pixels);
  if (grad) backend.upload(dg, grad, values);  // the gradient so far, which the kernel adds to
  const double loss = dafe_loss_launch(backend, buffers, da.data(), db.data(), dm.data(), width, height, channels,
                                       form, grad ? dg.data() : nullptr, scale);
  if (grad) {
    std::vector<float> out;
    backend.download(out, dg, values);
    std::copy(out.begin(), out.end(), grad);
  }
  return loss;
}

}  // namespace d2gs::train_kernels
