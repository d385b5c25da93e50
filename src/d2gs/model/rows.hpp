#pragma once
// Row edits on Gaussians-shaped arrays (the model, its gradients, Adam's moments): densification and
// pruning call these on all of them with the same arguments, so they stay aligned.
#include <cstdint>
#include <vector>

#include "d2gs/model/gaussians.hpp"

namespace d2gs {

// Keeps the rows whose flag is non-zero, in order.
void keep_rows(Gaussians& g, const std::vector<std::uint8_t>& keep);
// Returns the rows `indices` (in that order, repeats allowed).
Gaussians gather_rows(const Gaussians& g, const std::vector<std::uint32_t>& indices);
// Appends the rows of `tail` (same SH degree).
void append_rows(Gaussians& g, const Gaussians& tail);
// Sets every value to zero (quaternions included): the shape of a fresh gradient or moment.
void zero_values(Gaussians& g);

}  // namespace d2gs
