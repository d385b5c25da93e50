#include "d2gs/render/cpu/projection.hpp"

#include <algorithm>
#include <cstddef>
#include <type_traits>

#include "d2gs/render/activations.hpp"
#include "d2gs/render/raster_math.hpp"

// The VJP of four Gaussians at a time (float, SSE2 or wider): project_gaussian_vjp instantiated on a
// four-lane scalar type. Every operation of the scalar function is performed on each lane, in the same
// order (this file is compiled without floating-point contraction: no fused multiply-add can appear
// where the scalar code has none), so each lane's result is bit-identical to the scalar VJP's.
#if defined(__GNUC__) && defined(__SSE2__)
#define D2GS_PROJECTION_LANES 1
#endif

#if D2GS_PROJECTION_LANES
#include <xmmintrin.h>

namespace d2gs::render::cpu::lanes4 {

typedef float VF __attribute__((vector_size(16)));
typedef int VI __attribute__((vector_size(16)));

// Four floats that behave as one scalar of project_gaussian_vjp.
struct F4 {
  VF v;
  F4() = default;
  F4(float x) : v{x, x, x, x} {}                     // NOLINT: implicit, as float's own conversions
  F4(double x) : F4(static_cast<float>(x)) {}        // T(0.5): rounded to float first, as T(0.5) is
  F4(int x) : F4(static_cast<float>(x)) {}           // T(2), `T x = 0`
  static F4 of(VF x) {
    F4 r;
    r.v = x;
    return r;
  }
};
inline F4 operator+(F4 a, F4 b) { return F4::of(a.v + b.v); }
inline F4 operator-(F4 a, F4 b) { return F4::of(a.v - b.v); }
inline F4 operator*(F4 a, F4 b) { return F4::of(a.v * b.v); }
inline F4 operator/(F4 a, F4 b) { return F4::of(a.v / b.v); }
inline F4 operator-(F4 a) { return F4::of(-a.v); }
inline F4& operator+=(F4& a, F4 b) { return a = a + b; }
inline F4& operator-=(F4& a, F4 b) { return a = a - b; }

// A flag per lane (all bits set = true).
struct M4 {
  VI m;
};
inline F4 hd_select(M4 c, F4 a, F4 b) { return F4::of(c.m != 0 ? a.v : b.v); }

}  // namespace d2gs::render::cpu::lanes4

namespace d2gs::render {
template <>
struct StateFlag<cpu::lanes4::F4> {
  using type = cpu::lanes4::M4;
};
}  // namespace d2gs::render
#endif

namespace d2gs::render::cpu {

template <typename T>
void project_forward(const ModelView<T>& model, const T* opacity_multiplier, const CameraParams<T>& cam,
                     Projected<T>& out) {
  const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(model.count);
  out.resize(model.count);
  const int tiles_x = (cam.width + kTileSize - 1) / kTileSize;
  const int tiles_y = (cam.height + kTileSize - 1) / kTileSize;
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t i = 0; i < n; ++i) {
    const T m = opacity_multiplier ? opacity_multiplier[i] : T(1);
    const T s = sigmoid(model.opacity_logits[i]);
    out.opacity_sigmoid[i] = s;
    out.opacity[i] = s * m;
    ProjectionState<T>& st = out.state[i];
    int radius = 0;
    T* mean2d = &out.mean2d[i * 2];
    T* conic = &out.conic[i * 3];
    if (project_gaussian(model.means + i * 3, model.log_scales + i * 3, model.quats + i * 4, cam, mean2d, conic,
                         out.depth[i], radius, st)) {
      int rect[4];
      tile_rect(mean2d[0], mean2d[1], radius, tiles_x, tiles_y, rect);
      if ((rect[2] - rect[0]) * (rect[3] - rect[1]) == 0) radius = 0;
    }
    out.radii[i] = radius;
    if (radius == 0) {
      mean2d[0] = mean2d[1] = T(0);
      conic[0] = conic[1] = conic[2] = T(0);
      out.depth[i] = T(0);
    }
  }
}

namespace {

#if D2GS_PROJECTION_LANES
using lanes4::F4;
using lanes4::M4;
using lanes4::VF;
using lanes4::VI;

CameraParams<F4> broadcast(const CameraParams<float>& c) {
  CameraParams<F4> r;
  r.width = c.width;
  r.height = c.height;
  for (int k = 0; k < 9; ++k) r.R[k] = c.R[k];
  for (int k = 0; k < 3; ++k) {
    r.t[k] = c.t[k];
    r.campos[k] = c.campos[k];
  }
  r.fx = c.fx;
  r.fy = c.fy;
  r.cx = c.cx;
  r.cy = c.cy;
  r.lim_x_neg = c.lim_x_neg;
  r.lim_x_pos = c.lim_x_pos;
  r.lim_y_neg = c.lim_y_neg;
  r.lim_y_pos = c.lim_y_pos;
  return r;
}

// project_gaussian_vjp of the Gaussians idx[0..count-1] (count <= 4; the lanes past count repeat the
// last one and are not stored), from the forward's state and conic, into their zeroed gradient rows.
void vjp4(const int* idx, int count, const CameraParams<F4>& cam, const Projected<float>& fwd,
          const ProjectedGrads<float>& grads, const ModelGradView<float>& out) {
  int id[4];
  for (int l = 0; l < 4; ++l) id[l] = idx[l < count ? l : count - 1];
  const ProjectionState<float>* p[4] = {&fwd.state[id[0]], &fwd.state[id[1]], &fwd.state[id[2]],
                                        &fwd.state[id[3]]};
  const auto array = [&](const float* a, int stride, int k) {
    return F4::of(VF{a[id[0] * stride + k], a[id[1] * stride + k], a[id[2] * stride + k], a[id[3] * stride + k]});
  };
  // The four states, read as 4-byte words and transposed four words at a time: w[k] holds word k of
  // every lane. Words 0..47 cover every field the VJP reads (cov2, the last three, is not read); the
  // word of the two flags is not used as a float.
  using S = ProjectionState<float>;
  static_assert(sizeof(S) % 4 == 0 && offsetof(S, cov2) / 4 + 3 == sizeof(S) / 4 && offsetof(S, cov2) / 4 <= 48);
  VF w[48];
  for (int b = 0; b < 12; ++b) {
    __m128 r0 = _mm_loadu_ps(reinterpret_cast<const float*>(p[0]) + b * 4);
    __m128 r1 = _mm_loadu_ps(reinterpret_cast<const float*>(p[1]) + b * 4);
    __m128 r2 = _mm_loadu_ps(reinterpret_cast<const float*>(p[2]) + b * 4);
    __m128 r3 = _mm_loadu_ps(reinterpret_cast<const float*>(p[3]) + b * 4);
    _MM_TRANSPOSE4_PS(r0, r1, r2, r3);
    w[b * 4 + 0] = r0;
    w[b * 4 + 1] = r1;
    w[b * 4 + 2] = r2;
    w[b * 4 + 3] = r3;
  }
  const auto word = [&](std::size_t offset, int k) { return F4::of(w[offset / 4 + static_cast<std::size_t>(k)]); };
  ProjectionState<F4> st;
  for (int k = 0; k < 3; ++k) st.pc[k] = word(offsetof(S, pc), k);
  st.u = word(offsetof(S, u), 0);
  st.v = word(offsetof(S, v), 0);
  st.u_free = M4{VI{-int(p[0]->u_free), -int(p[1]->u_free), -int(p[2]->u_free), -int(p[3]->u_free)}};
  st.v_free = M4{VI{-int(p[0]->v_free), -int(p[1]->v_free), -int(p[2]->v_free), -int(p[3]->v_free)}};
  for (int k = 0; k < 6; ++k) st.A[k] = word(offsetof(S, A), k);
  for (int k = 0; k < 9; ++k) {
    st.sigma[k] = word(offsetof(S, sigma), k);
    st.M[k] = word(offsetof(S, M), k);
    st.Rq[k] = word(offsetof(S, Rq), k);
  }
  for (int k = 0; k < 4; ++k) st.qn[k] = word(offsetof(S, qn), k);
  st.qnorm = word(offsetof(S, qnorm), 0);
  for (int k = 0; k < 3; ++k) st.s[k] = word(offsetof(S, s), k);
  for (int k = 0; k < 3; ++k) st.cov2[k] = F4(0);
  const F4 conic[3] = {array(fwd.conic.data(), 3, 0), array(fwd.conic.data(), 3, 1), array(fwd.conic.data(), 3, 2)};
  const F4 d_mean2d[2] = {array(grads.mean2d.data(), 2, 0), array(grads.mean2d.data(), 2, 1)};
  const F4 d_conic[3] = {array(grads.conic.data(), 3, 0), array(grads.conic.data(), 3, 1),
                         array(grads.conic.data(), 3, 2)};
  const F4 d_depth = array(grads.depth.data(), 1, 0);
  // The scalar path zeroes the rows and accumulates into them (0 + ...): the same here, per lane.
  F4 dm[3] = {F4(0), F4(0), F4(0)}, ds[3] = {F4(0), F4(0), F4(0)}, dq[4] = {F4(0), F4(0), F4(0), F4(0)};
  project_gaussian_vjp<F4>(nullptr, nullptr, nullptr, cam, st, conic, d_mean2d, d_conic, d_depth, dm, ds, dq);
  for (int l = 0; l < count; ++l) {
    const std::ptrdiff_t i = id[l];
    for (int k = 0; k < 3; ++k) out.means[i * 3 + k] = dm[k].v[l];
    for (int k = 0; k < 3; ++k) out.log_scales[i * 3 + k] = ds[k].v[l];
    for (int k = 0; k < 4; ++k) out.quats[i * 4 + k] = dq[k].v[l];
  }
}
#endif

// Gaussian i's share of the backward that both loops do: its geometry gradients zeroed (the VJP adds to
// them), and its opacity-logit gradient through the multiplier and the sigmoid. False for a culled Gaussian,
// whose gradients stay zero.
template <typename T>
inline bool zero_and_opacity_grad(std::ptrdiff_t i, const T* opacity_multiplier, const Projected<T>& fwd,
                                  const ProjectedGrads<T>& grads, const ModelGradView<T>& out) {
  T* dm = out.means + i * 3;
  T* ds = out.log_scales + i * 3;
  T* dq = out.quats + i * 4;
  dm[0] = dm[1] = dm[2] = T(0);
  ds[0] = ds[1] = ds[2] = T(0);
  dq[0] = dq[1] = dq[2] = dq[3] = T(0);
  out.opacity_logits[i] = T(0);
  if (fwd.radii[i] <= 0) return false;
  const T m = opacity_multiplier ? opacity_multiplier[i] : T(1);
  const T s = fwd.opacity_sigmoid[i];
  out.opacity_logits[i] = grads.opacity[i] * m * s * (T(1) - s);
  return true;
}

}  // namespace

template <typename T>
void project_backward(const ModelView<T>& model, const T* opacity_multiplier, const CameraParams<T>& cam,
                      const Projected<T>& fwd, const ProjectedGrads<T>& grads, const ModelGradView<T>& out) {
  const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(model.count);
#if D2GS_PROJECTION_LANES
  if constexpr (std::is_same_v<T, float>) {
    const CameraParams<F4> cam4 = broadcast(cam);
    constexpr std::ptrdiff_t kBlock = 256;
    const std::ptrdiff_t blocks = (n + kBlock - 1) / kBlock;
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t b = 0; b < blocks; ++b) {
      int idx[4];
      int count = 0;
      const std::ptrdiff_t end = std::min(n, (b + 1) * kBlock);
      for (std::ptrdiff_t i = b * kBlock; i < end; ++i) {
        if (!zero_and_opacity_grad(i, opacity_multiplier, fwd, grads, out)) continue;
        idx[count++] = static_cast<int>(i);
        if (count == 4) {
          vjp4(idx, 4, cam4, fwd, grads, out);
          count = 0;
        }
      }
      if (count > 0) vjp4(idx, count, cam4, fwd, grads, out);
    }
    return;
  }
#endif
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t i = 0; i < n; ++i) {
    if (!zero_and_opacity_grad(i, opacity_multiplier, fwd, grads, out)) continue;
    T* dm = out.means + i * 3;
    T* ds = out.log_scales + i * 3;
    T* dq = out.quats + i * 4;
    // The forward's state and conic (a Gaussian with radius > 0 keeps project_gaussian's values).
    project_gaussian_vjp(model.means + i * 3, model.log_scales + i * 3, model.quats + i * 4, cam, fwd.state[i],
                         &fwd.conic[i * 3], &grads.mean2d[i * 2], &grads.conic[i * 3], grads.depth[i], dm, ds, dq);
  }
}

template void project_forward<float>(const ModelView<float>&, const float*, const CameraParams<float>&,
                                     Projected<float>&);
template void project_forward<double>(const ModelView<double>&, const double*, const CameraParams<double>&,
                                      Projected<double>&);
template void project_backward<float>(const ModelView<float>&, const float*, const CameraParams<float>&,
                                      const Projected<float>&, const ProjectedGrads<float>&,
                                      const ModelGradView<float>&);
template void project_backward<double>(const ModelView<double>&, const double*, const CameraParams<double>&,
                                       const Projected<double>&, const ProjectedGrads<double>&,
                                       const ModelGradView<double>&);

}  // namespace d2gs::render::cpu
