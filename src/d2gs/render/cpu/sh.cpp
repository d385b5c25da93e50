#include "d2gs/render/cpu/sh.hpp"

#include "d2gs/render/sh_math.hpp"

namespace d2gs::render::cpu {

template <typename T>
void sh_forward(const ModelView<T>& model, int active_degree, const CameraParams<T>& cam, Projected<T>& out) {
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
    sh_to_color(active_degree, model.sh_dc + i * 3, model.sh_rest + i * K * 3, model.means + i * 3, cam.campos,
                color, cl);
    for (int c = 0; c < 3; ++c) clamped[c] = cl[c] ? 1 : 0;
  }
}

template <typename T>
void sh_backward(const ModelView<T>& model, int active_degree, const CameraParams<T>& cam,
                 const Projected<T>& fwd, const T* d_color, const ModelGradView<T>& out) {
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
    sh_to_color_vjp(active_degree, model.sh_dc + i * 3, model.sh_rest + i * K * 3, model.means + i * 3, cam.campos,
                    cl, d_color + i * 3, ddc, drest, out.means + i * 3);
  }
}

template void sh_forward<float>(const ModelView<float>&, int, const CameraParams<float>&, Projected<float>&);
template void sh_forward<double>(const ModelView<double>&, int, const CameraParams<double>&, Projected<double>&);
template void sh_backward<float>(const ModelView<float>&, int, const CameraParams<float>&, const Projected<float>&,
                                 const float*, const ModelGradView<float>&);
template void sh_backward<double>(const ModelView<double>&, int, const CameraParams<double>&,
                                  const Projected<double>&, const double*, const ModelGradView<double>&);

}  // namespace d2gs::render::cpu
