#pragma once
// Maps with one value per pixel of a training view, one file a view: DIR/NAME.npy (H×W, NAME the view's
// image name without its extension), such as d2gs init's stereo depth maps (geometry/training_geometry.hpp)
// or DAFE's prior maps. The regularisers that use them read them here, at the view's size.
#include <filesystem>
#include <string_view>

#include "d2gs/core/image.hpp"
#include "d2gs/scene/camera.hpp"

namespace d2gs {

struct ViewMapRead {
  // What the map is, in the error for a missing file ("{what} missing for training view NAME").
  std::string_view what;
  // What the file must hold, in the error for one that is not 2-D ("expected an H×W {shape}, got …").
  std::string_view shape;
  // 0 means "no value" (depth maps): a map of another size is resized with resize_area_nonzero, which
  // never averages 0 into the values; otherwise with resize_area.
  bool zero_is_none = false;
  // Every value must be a depth (finite and ≥ 0); an error names the first that is not.
  bool check_depths = false;
};

// The map DIR/NAME.npy of camera `cam` as a one-channel image at the camera's size (a map of another
// size, e.g. at the scene folder's highest resolution, is resized as `read` says). Errors name the file.
Image read_view_map(const std::filesystem::path& dir, const Camera& cam, const ViewMapRead& read);

}  // namespace d2gs
