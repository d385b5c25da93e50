#pragma once
// Scene loading: COLMAP sparse/0 (binary or text), LLFF poses_bounds.npy, Blender transforms_*.json.
// A Scene holds metadata only (cameras, image paths and sizes, the dataset's own SfM points); images are
// decoded on demand by load_image(), so a command touches only the views it uses.
#include <filesystem>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "d2gs/core/image.hpp"
#include "d2gs/model/point_cloud.hpp"
#include "d2gs/scene/camera.hpp"

namespace d2gs {

enum class SceneFormat { Colmap, Llff, Blender };
const char* to_string(SceneFormat format);

// Where the images at resolution R come from (`--image-source`):
//   Folder:  images_R/ when present, else a larger images_F/ area-resampled by R/F (the prepared folders);
//   Largest: the largest image folder present (images/, else the smallest F of images_F/), resized by R/F
//            with PIL's bicubic filter (core/resize_pil.hpp), as the original 3DGS loader resizes the
//            full-resolution images/ (training images and the ground truth it scores against).
enum class ImageSource { Folder, Largest };
const char* to_string(ImageSource source);
ImageSource image_source_from_string(const std::string& s);  // "folder" | "largest"; throws otherwise
// The commands' default (d2gs train, init, info, render): the original loader's images, so that a PSNR is
// measured on the pixels the papers measure it on (issue 23; docs/training.md). The loader's own default
// below stays the folder asked for.
inline constexpr ImageSource kDefaultImageSource = ImageSource::Largest;

struct SceneLoadOptions {
  int resolution = 1;                  // -r: 1, 2, 4 or 8 (1/R of full resolution)
  glm::vec3 background{0.0f};          // RGBA images are composited on this colour
  ImageSource image_source = ImageSource::Folder;
};

struct Scene {
  std::filesystem::path root;
  SceneFormat format = SceneFormat::Colmap;
  std::string images_folder;           // folder the images are read from, relative to root
  int resolution = 1;
  ImageSource image_source = ImageSource::Folder;  // also picks the resampling filter of load_image
  glm::vec3 background{0.0f};
  std::vector<Camera> cameras;         // global image index = position in this list
  // Blender only: the dataset's own split (global indices); empty for COLMAP/LLFF.
  std::vector<int> dataset_train;
  std::vector<int> dataset_test;
  // The dataset's points3D (triangulated from ALL views, including test views: an oracle).
  PointCloud sfm_points;
  std::vector<std::string> warnings;   // non-fatal problems met while loading (also logged)
};

// Detects the format of `root` and loads it: sparse/0/images.{bin,txt} -> COLMAP, else
// poses_bounds.npy -> LLFF, else transforms_train.json -> Blender (docs/formats.md, "Scenes"). Throws d2gs::Error naming the file and the problem.
Scene load_scene(const std::filesystem::path& root, const SceneLoadOptions& options = {});
// A scene without cameras: `root`, `format` and the load options recorded (each format loader starts from it).
Scene empty_scene(const std::filesystem::path& root, SceneFormat format, const SceneLoadOptions& options);
// Decodes camera `index`'s image at the scene's resolution: RGB float [0,1], alpha composited on the
// scene's background, resampled when needed (area, or PIL's bicubic for ImageSource::Largest); throws if
// its size differs from the camera's.
Image load_image(const Scene& scene, int index);

// ---- resolution handling, shared by the format loaders ----

// Throws unless resolution is 1, 2, 4 or 8.
void check_resolution(int resolution);

// Where the images of an LLFF/COLMAP scene are read from at resolution R.
struct ImageFolderChoice {
  std::string folder;     // relative to the scene root: "images" (F = 1) or "images_F"
  int folder_factor = 1;  // F: the folder holds 1/F of full resolution
  int resample = 1;       // R / F: further area downsampling applied on load
};
// Folder: images_R/ (images/ for R = 1) when it exists, otherwise images_F for the largest F dividing R
// that exists. Largest: images_F for the smallest F dividing R that exists (images/ first). A folder is
// only ever downsampled. Throws naming the root and the folders looked for.
ImageFolderChoice choose_image_folder(const std::filesystem::path& root, int resolution,
                                      ImageSource source = ImageSource::Folder);

// Length of an image side after area resampling by `factor`: round_half_even(length / factor), at
// least 1 (the rounding of the 3DGS loader, whose Python round() is half-to-even).
int resampled_length(int length, int factor);

// Fills camera.width/height/resample_factor/has_alpha from the header of camera.image_path (the image
// is not decoded): the file's size divided by `resample`. Throws naming the file when it is missing.
void set_camera_image(Camera& camera, int resample);

}  // namespace d2gs
