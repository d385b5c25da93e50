#include "d2gs/render/cpu/sh.hpp"

#include "d2gs/render/sh_math.hpp"

namespace d2gs::render::cpu {
namespace {

// One Gaussian's colour and its VJP at a degree known at compile time: flatten inlines the shared
// sh_math.hpp functions with the degree a constant, so their loops over the coefficients unroll and
// the basis terms of higher degrees disappear. The arithmetic is the functions' own. D = -1: the degree
// given at run time (one outside 0..3).
template <int D, typename T>
[[gnu::flatten]] void color_at_degree(int degree, const T* sh_dc, const T* sh_rest, const T* mean, const T* campos,
                                      T* color, bool* clamped) {
  sh_to_color(D >= 0 ? D : degree, sh_dc, sh_rest, mean, campos, color, clamped);
}

template <int D, typename T>
[[gnu::flatten]] void color_vjp_at_degree(int degree, const T* sh_dc, const T* sh_rest, const T* mean,
                                          const T* campos, const bool* clamped, const T* d_color, T* d_sh_dc,
                                          T* d_sh_rest, T* d_mean) {
  sh_to_color_vjp(D >= 0 ? D : degree, sh_dc, sh_rest, mean, campos, clamped, d_color, d_sh_dc, d_sh_rest, d_mean);
}

template <int D, typename T>
void forward_at_degree(int degree, const ModelView<T>& model, const CameraParams<T>& cam, Projected<T>& out) {
  const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(model.count);
  const int K = model.sh_rest_count();
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t i = 0; i < n; ++i) {
    T* color = &out.color[i * 3];
    std::uint8_t* clamped = &out.color_clamped[i * 3];
    if (out.radii[i] <= 0) {
      color[0] = color[1] = color[2] = T(0);
      clamped[0] = clamped[1] = clamped[2] = 1;
      continue;
    }
    bool cl[3];
    color_at_degree<D>(degree, model.sh_dc + i * 3, model.sh_rest + i * K * 3, model.means + i * 3, cam.campos, color, cl);
    for (int c = 0; c < 3; ++c) clamped[c] = cl[c] ? 1 : 0;
  }
}

template <int D, typename T>
void backward_at_degree(int degree, const ModelView<T>& model, const CameraParams<T>& cam, const Projected<T>& fwd,
                        const T* d_color, const ModelGradView<T>& out) {
  const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(model.count);
  const int K = model.sh_rest_count();
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t i = 0; i < n; ++i) {
    T* ddc = out.sh_dc + i * 3;
    T* drest = out.sh_rest + i * K * 3;
    ddc[0] = ddc[1] = ddc[2] = T(0);
    for (int k = 0; k < K * 3; ++k) drest[k] = T(0);
    if (fwd.radii[i] <= 0) continue;
    const bool cl[3] = {fwd.color_clamped[i * 3] != 0, fwd.color_clamped[i * 3 + 1] != 0,
                        fwd.color_clamped[i * 3 + 2] != 0};
    color_vjp_at_degree<D>(degree, model.sh_dc + i * 3, model.sh_rest + i * K * 3, model.means + i * 3, cam.campos, cl,
                           d_color + i * 3, ddc, drest, out.means + i * 3);
  }
}

}  // namespace

template <typename T>
void sh_forward(const ModelView<T>& model, int active_degree, const CameraParams<T>& cam, Projected<T>& out) {
  switch (active_degree) {
    case 0: return forward_at_degree<0>(0, model, cam, out);
    case 1: return forward_at_degree<1>(1, model, cam, out);
    case 2: return forward_at_degree<2>(2, model, cam, out);
    case 3: return forward_at_degree<3>(3, model, cam, out);
    default: return forward_at_degree<-1>(active_degree, model, cam, out);
  }
}

template <typename T>
void sh_backward(const ModelView<T>& model, int active_degree, const CameraParams<T>& cam,
                 const Projected<T>& fwd, const T* d_color, const ModelGradView<T>& out) {
  switch (active_degree) {
    case 0: return backward_at_degree<0>(0, model, cam, fwd, d_color, out);
    case 1: return backward_at_degree<1>(1, model, cam, fwd, d_color, out);
    case 2: return backward_at_degree<2>(2, model, cam, fwd, d_color, out);
    case 3: return backward_at_degree<3>(3, model, cam, fwd, d_color, out);
    default: return backward_at_degree<-1>(active_degree, model, cam, fwd, d_color, out);
  }
}

template void sh_forward<float>(const ModelView<float>&, int, const CameraParams<float>&, Projected<float>&);
template void sh_forward<double>(const ModelView<double>&, int, const CameraParams<double>&, Projected<double>&);
template void sh_backward<float>(const ModelView<float>&, int, const CameraParams<float>&, const Projected<float>&,
                                 const float*, const ModelGradView<float>&);
template void sh_backward<double>(const ModelView<double>&, int, const CameraParams<double>&,
                                  const Projected<double>&, const double*, const ModelGradView<double>&);

}  // namespace d2gs::render::cpu
