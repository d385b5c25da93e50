#pragma once
// Parameter activations of method.md §2 (shared by the CPU and CUDA backends, the trainer and eval's
// Gaussian mixtures): opacity = sigmoid(logit), in float and in double.
#include <cmath>

#include "d2gs/core/host_device.hpp"

namespace d2gs {

D2GS_HD float sigmoid(float x) { return 1.0f / (1.0f + expf(-x)); }
D2GS_HD double sigmoid(double x) { return 1.0 / (1.0 + exp(-x)); }
D2GS_HD float inverse_sigmoid(float y) { return logf(y / (1.0f - y)); }

}  // namespace d2gs
