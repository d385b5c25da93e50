#pragma once
// COLMAP sparse models (cameras, images, points3D) in COLMAP's binary and text formats: parsers that
// take bytes (every read bounds-checked, counts capped by the bytes left, so truncated or hostile input
// throws d2gs::Error naming the file and never over-allocates), writers, and the scene loader.
#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "d2gs/model/point_cloud.hpp"
#include "d2gs/scene/scene.hpp"

namespace d2gs {

// COLMAP camera model ids (colmap/sensor/models.h).
enum class ColmapCameraModel : int {
  SimplePinhole = 0,
  Pinhole = 1,
  SimpleRadial = 2,
  Radial = 3,
  OpenCV = 4,
  OpenCVFisheye = 5,
  FullOpenCV = 6,
  FOV = 7,
  SimpleRadialFisheye = 8,
  RadialFisheye = 9,
  ThinPrismFisheye = 10,
  RadTanThinPrismFisheye = 11,
};
// "PINHOLE", ...; "UNKNOWN" for ids outside the table.
const char* colmap_model_name(int model_id);
// Number of parameters of the model; -1 for an unknown id.
int colmap_model_num_params(int model_id);
// Model id from its name; -1 when unknown.
int colmap_model_id(std::string_view name);

struct ColmapCamera {
  std::uint32_t id = 0;
  int model_id = 1;
  std::uint64_t width = 0;
  std::uint64_t height = 0;
  std::vector<double> params;  // as COLMAP orders them (PINHOLE: fx fy cx cy)
};

struct ColmapImage {
  std::uint32_t id = 0;
  std::array<double, 4> qvec{1, 0, 0, 0};  // world-to-camera rotation, (w, x, y, z)
  std::array<double, 3> tvec{0, 0, 0};     // world-to-camera translation
  std::uint32_t camera_id = 0;
  std::string name;
  std::vector<std::array<double, 2>> xys;  // 2D observations
  std::vector<std::int64_t> point3D_ids;   // same length as xys; -1 = none
};

struct ColmapTrackElement {
  std::uint32_t image_id = 0;
  std::uint32_t point2D_idx = 0;
};

struct ColmapPoint3D {
  std::uint64_t id = 0;
  std::array<double, 3> xyz{0, 0, 0};
  std::array<std::uint8_t, 3> rgb{0, 0, 0};
  double error = 0;
  std::vector<ColmapTrackElement> track;
};

// A model in file order (records are kept in the order the file lists them).
struct ColmapModel {
  std::vector<ColmapCamera> cameras;
  std::vector<ColmapImage> images;
  std::vector<ColmapPoint3D> points;
};

// Parsers: `source` names the file in error messages.
std::vector<ColmapCamera> parse_colmap_cameras_bin(std::string_view bytes, const std::filesystem::path& source);
std::vector<ColmapImage> parse_colmap_images_bin(std::string_view bytes, const std::filesystem::path& source);
std::vector<ColmapPoint3D> parse_colmap_points3D_bin(std::string_view bytes, const std::filesystem::path& source);
std::vector<ColmapCamera> parse_colmap_cameras_txt(std::string_view text, const std::filesystem::path& source);
std::vector<ColmapImage> parse_colmap_images_txt(std::string_view text, const std::filesystem::path& source);
std::vector<ColmapPoint3D> parse_colmap_points3D_txt(std::string_view text, const std::filesystem::path& source);

// Reads <dir>/<name>.bin, or <name>.txt when there is no .bin. Throws naming what was looked for.
std::vector<ColmapCamera> read_colmap_cameras(const std::filesystem::path& dir);
std::vector<ColmapImage> read_colmap_images(const std::filesystem::path& dir);
std::vector<ColmapPoint3D> read_colmap_points3D(const std::filesystem::path& dir);
ColmapModel read_colmap_model(const std::filesystem::path& dir);
// True when <dir> holds points3D.bin or points3D.txt.
bool has_colmap_points3D(const std::filesystem::path& dir);

// Serialisers (bytes/text exactly as COLMAP writes them; text numbers in shortest round-trip form).
std::string colmap_cameras_bin(const std::vector<ColmapCamera>& cameras);
std::string colmap_images_bin(const std::vector<ColmapImage>& images);
std::string colmap_points3D_bin(const std::vector<ColmapPoint3D>& points);
std::string colmap_cameras_txt(const std::vector<ColmapCamera>& cameras);
std::string colmap_images_txt(const std::vector<ColmapImage>& images);
std::string colmap_points3D_txt(const std::vector<ColmapPoint3D>& points);
// Write {cameras,images,points3D}.{bin,txt} into `dir` (created if needed), each file atomically.
void write_colmap_binary(const ColmapModel& model, const std::filesystem::path& dir);
void write_colmap_text(const ColmapModel& model, const std::filesystem::path& dir);

// Oracle cloud from points3D (throws naming `source` on a non-finite position).
PointCloud colmap_point_cloud(const std::vector<ColmapPoint3D>& points, const std::filesystem::path& source);
// World-to-camera rotation of a unit (w, x, y, z) quaternion (normalised here; throws on zero / NaN).
glm::dmat3 colmap_quaternion_to_matrix(const std::array<double, 4>& qvec, const std::filesystem::path& source);

// Loads a scene from <root>/sparse/0 (binary or text) and the images folder chosen for the resolution.
Scene load_colmap_scene(const std::filesystem::path& root, const SceneLoadOptions& options);

}  // namespace d2gs
