#include "d2gs/render/cpu/projection.hpp"

#include "d2gs/render/activations.hpp"
#include "d2gs/render/raster_math.hpp"

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

template <typename T>
void project_backward(const ModelView<T>& model, const T* opacity_multiplier, const CameraParams<T>& cam,
                      const Projected<T>& fwd, const ProjectedGrads<T>& grads, const ModelGradView<T>& out) {
  const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(model.count);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t i = 0; i < n; ++i) {
    T* dm = out.means + i * 3;
    T* ds = out.log_scales + i * 3;
    T* dq = out.quats + i * 4;
    dm[0] = dm[1] = dm[2] = T(0);
    ds[0] = ds[1] = ds[2] = T(0);
    dq[0] = dq[1] = dq[2] = dq[3] = T(0);
    out.opacity_logits[i] = T(0);
    if (fwd.radii[i] <= 0) continue;
    const T m = opacity_multiplier ? opacity_multiplier[i] : T(1);
    const T s = fwd.opacity_sigmoid[i];
    out.opacity_logits[i] = grads.opacity[i] * m * s * (T(1) - s);
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
