#pragma once
// Image resizing as the original 3DGS loader does it: PIL's `Image.resize(size)` with its default filter
// (bicubic, a = -0.5) on 8-bit images. PIL's resampling is separable (horizontal pass, then vertical),
// widens the filter's support by the scale when it shrinks (antialiasing: support 2·scale input pixels),
// normalises each output pixel's weights, and on 8-bit images works in fixed point (22 fractional bits)
// with the intermediate image rounded and clipped to 8 bits. This reproduces that arithmetic, so an image
// read from the same file gives the same bytes as Pillow (checked against Pillow on real images by
// tests/core, fixture from tools/make_pil_resize_fixture.py).
#include "d2gs/core/image.hpp"

namespace d2gs {

// `image` holds 8-bit values scaled to [0, 1] (as read_image returns them); they are requantised with
// round(v * 255) before resampling. Any channel count; channels are resampled independently (PIL's RGB and
// L modes; RGBA images should be composited before, as the loader does). Throws for an empty target size.
Image resize_pil_bicubic(const Image& image, int width, int height);

}  // namespace d2gs
