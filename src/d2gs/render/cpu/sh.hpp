#pragma once
// Stage 2: spherical harmonics -> RGB per Gaussian (sh_math.hpp), and its backward pass.
#include "d2gs/render/cpu/types.hpp"

namespace d2gs::render::cpu {

// Colour of every Gaussian with radii > 0 at the active degree (<= model.sh_degree); 0 for the others.
template <typename T>
void sh_forward(const ModelView<T>& model, int active_degree, const CameraParams<T>& cam, Projected<T>& out);

// Assigns d_sh_dc and d_sh_rest (all coefficients; zero beyond the active degree) and ADDS the
// view-direction term to d_means.
template <typename T>
void sh_backward(const ModelView<T>& model, int active_degree, const CameraParams<T>& cam,
                 const Projected<T>& fwd, const T* d_color, const ModelGradView<T>& out);

}  // namespace d2gs::render::cpu
