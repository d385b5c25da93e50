#pragma once
// Spherical harmonics -> colour, forward and backward, one thread per Gaussian (gsplat's
// SphericalHarmonicsCUDA): the per-Gaussian work of cpu/sh.cpp around the shared sh_to_color() and its VJP.
#include <stdint.h>

#include "d2gs/render/kernels/block.hpp"
#include "d2gs/render/sh_math.hpp"

namespace d2gs::render::kernels {

struct ShFwdArgs {
  int n = 0;
  int active_degree = 0;  // <= the model's degree
  int rest_count = 0;     // coefficients per Gaussian in sh_rest ((model degree + 1)^2 - 1)
  const float* means = nullptr;
  const float* sh_dc = nullptr;    // N x 3
  const float* sh_rest = nullptr;  // N x rest_count x 3
  const int* radii = nullptr;
  float campos[3] = {0, 0, 0};
  float* color = nullptr;          // N x 3 (0 where culled)
  uint8_t* color_clamped = nullptr;  // N x 3 (1 where culled)
};

D2GS_HD void sh_fwd_thread(int i, const ShFwdArgs& a) {
  float* color = a.color + i * 3;
  uint8_t* clamped = a.color_clamped + i * 3;
  if (a.radii[i] <= 0) {
    color[0] = color[1] = color[2] = 0.0f;
    clamped[0] = clamped[1] = clamped[2] = 1;
    return;
  }
  bool cl[3];
  sh_to_color(a.active_degree, a.sh_dc + i * 3, a.sh_rest + i * a.rest_count * 3, a.means + i * 3, a.campos, color,
              cl);
  for (int c = 0; c < 3; ++c) clamped[c] = cl[c] ? 1 : 0;
}

using ShFwdKernel = PerItemKernel<ShFwdArgs, sh_fwd_thread>;

struct ShBwdArgs {
  int n = 0, active_degree = 0, rest_count = 0;
  const float* means = nullptr;
  const float* sh_dc = nullptr;
  const float* sh_rest = nullptr;
  const int* radii = nullptr;
  const uint8_t* color_clamped = nullptr;
  float campos[3] = {0, 0, 0};
  const float* d_color = nullptr;  // N x 3
  float* d_sh_dc = nullptr;        // assigned
  float* d_sh_rest = nullptr;      // assigned (zero beyond the active degree)
  float* d_means = nullptr;        // the view-direction term is added
};

D2GS_HD void sh_bwd_thread(int i, const ShBwdArgs& a) {
  float* ddc = a.d_sh_dc + i * 3;
  float* drest = a.d_sh_rest + i * a.rest_count * 3;
  ddc[0] = ddc[1] = ddc[2] = 0.0f;
  for (int k = 0; k < a.rest_count * 3; ++k) drest[k] = 0.0f;
  if (a.radii[i] <= 0) return;
  const bool cl[3] = {a.color_clamped[i * 3] != 0, a.color_clamped[i * 3 + 1] != 0, a.color_clamped[i * 3 + 2] != 0};
  sh_to_color_vjp(a.active_degree, a.sh_dc + i * 3, a.sh_rest + i * a.rest_count * 3, a.means + i * 3, a.campos, cl,
                  a.d_color + i * 3, ddc, drest, a.d_means + i * 3);
}

using ShBwdKernel = PerItemKernel<ShBwdArgs, sh_bwd_thread>;

}  // namespace d2gs::render::kernels
