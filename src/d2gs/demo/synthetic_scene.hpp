#pragma once
// The built-in synthetic demo scene: an analytic ray tracer (no Gaussian renderer involved) of textured
// planes, spheres and boxes at several depths before a distant textured backdrop, seen by LLFF-like
// forward-facing cameras. `write_synthetic_scene` stores it in the LLFF layout the scene loader reads,
// together with its true geometry:
//   DIR/images/image000.png ...   RGB, 8-bit, width x height (full resolution = generated size)
//   DIR/poses_bounds.npy          N x 17 float64, LLFF convention (docs/formats.md, SOURCES.md)
//   DIR/depth/image000.npy ...    float32 H x W: view-space z of the first hit through each pixel centre
//   DIR/points3D.ply              coloured points sampled on the true visible surfaces (oracle)
//   DIR/scene.json                objects, light, cameras, seed, options
//
// World frame: x right, y down, z forward (away from the cameras), i.e. the OpenCV camera frame of a
// camera at the origin looking at the scene. The ground is the plane y = 1.2 (below the cameras), the
// backdrop the plane z = 40. Cameras sit on a small grid in the plane z = 0 (about 1.0 x 0.6 units,
// 5 x 4 for 20 views, numbered row by row from the top left) and all look at a focus point near
// (0, 0.1, 9), so they face +z with a few degrees of toe-in, as in a hand-held LLFF capture. Nearest surfaces are about 2.5 units away, the backdrop about 40:
// a near and a far field. Everything (layout jitter, colours, texture phases) follows from the seed;
// the output is bit-identical for equal options, whatever the thread count.
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include <glm/glm.hpp>
#include <nlohmann/json.hpp>

#include "d2gs/core/image.hpp"
#include "d2gs/model/point_cloud.hpp"
#include "d2gs/scene/camera.hpp"

namespace d2gs {

struct SyntheticSceneOptions {
  int width = 504;          // image size (LLFF at 1/8 resolution)
  int height = 378;
  int views = 20;           // cameras (2..1000)
  int supersample = 3;      // s x s rays per pixel, box-filtered (1..8)
  std::uint64_t seed = 0;
  double focal = 0.0;       // pixels (fx = fy); 0: 407.566 * width / 504, fern's focal length at 1/8
  int points = 10000;       // approximate size of points3D.ply
};

// Throws d2gs::Error naming the option when one is out of range.
void validate(const SyntheticSceneOptions& options);

struct SyntheticHit {
  bool hit = false;
  double depth = 0.0;           // view-space z (distance along the optical axis)
  glm::dvec3 position{0.0};     // world
  glm::dvec3 normal{0.0};       // world, unit, facing the ray
  glm::vec3 color{0.0f};        // shaded colour at the hit, RGB in [0, 1]
  int object = -1;              // index into SyntheticScene::describe()["objects"]
};

class SyntheticScene {
public:
  explicit SyntheticScene(const SyntheticSceneOptions& options = {});

  const SyntheticSceneOptions& options() const { return options_; }
  // The cameras, in image order (image000.png, image001.png, ...); image paths relative to DIR.
  const std::vector<Camera>& cameras() const { return cameras_; }

  // Traces the ray through pixel coordinates (px, py) of `camera` (pixel (x, y) covers [x, x+1) x
  // [y, y+1); its centre is (x + 0.5, y + 0.5)).
  SyntheticHit trace(const Camera& camera, double px, double py) const;
  // View-space z of the first hit through the centre of pixel (x, y) (the backdrop catches every ray).
  double trace_depth(const Camera& camera, int x, int y) const;

  // The supersampled RGB image of a camera (OpenMP-parallel over rows unless already in a parallel region).
  Image render(const Camera& camera) const;
  // H x W row-major depth map of trace_depth at every pixel centre.
  std::vector<float> depth_map(const Camera& camera) const;
  // Points on the surfaces visible from camera `view` (a jittered grid of about `count` pixels), with
  // their shaded colours.
  PointCloud sample_points(int view, int count) const;

  // Objects, light, cameras and options as JSON (the content of scene.json, without bookkeeping).
  nlohmann::json describe() const;

  struct Object;  // defined in synthetic_scene.cpp
  ~SyntheticScene();
  SyntheticScene(const SyntheticScene&);
  SyntheticScene& operator=(const SyntheticScene&);

private:
  SyntheticSceneOptions options_;
  std::vector<Camera> cameras_;
  std::vector<Object> objects_;
  glm::dvec3 to_light_{0.0};
  glm::dvec3 focus_{0.0};
  // Conservative pixel rectangle of an object's projection (planes: everywhere).
  struct ScreenRect {
    double x0 = -1e300, y0 = -1e300, x1 = 1e300, y1 = 1e300;
    bool contains(double x, double y) const { return x >= x0 && x <= x1 && y >= y0 && y <= y1; }
  };
  // A camera prepared for tracing many rays.
  struct View {
    glm::dvec3 origin{0.0};
    glm::dmat3 cam_to_world{1.0};
    double fx = 1, fy = 1, cx = 0, cy = 0;
    std::vector<ScreenRect> rects;  // empty: no culling
  };
  View prepare(const Camera& camera, bool cull) const;
  SyntheticHit trace(const View& view, double px, double py, bool shade) const;
  SyntheticHit intersect(const glm::dvec3& origin, const glm::dvec3& direction, const ScreenRect* rects, double px,
                         double py) const;
  bool occluded(const glm::dvec3& origin, const glm::dvec3& direction) const;
  glm::vec3 shade(const SyntheticHit& hit, const glm::dvec3& direction, double footprint) const;
};

// The cameras of the scene with these options (same as SyntheticScene(options).cameras()).
std::vector<Camera> synthetic_scene_cameras(const SyntheticSceneOptions& options);

// The generator's mark in scene.json.
inline constexpr const char* kSyntheticSceneGenerator = "d2gs synthetic scene";
// The lock file by which `d2gs demo` holds its output folder while it writes the scene and trains in it
// (core/file_lock.hpp's FolderWriteLock); write_synthetic_scene counts a folder holding only it as empty.
inline constexpr const char* kSyntheticSceneLock = ".d2gs-demo.lock";
// True when `dir` holds a scene.json written by write_synthetic_scene.
bool is_synthetic_scene(const std::filesystem::path& dir);

// Writes the scene to `dir` (created if needed). Refuses (d2gs::Error) a path that is a file, or a
// non-empty folder without the scene.json of a previous synthetic scene, so that it never overwrites
// user data; in a previous synthetic scene it replaces its own files (and removes images/depth files of
// views that no longer exist) and leaves everything else alone. Every file is written atomically.
// `progress(done, total)` is called after each view (from one thread at a time); an exception it throws
// ends the write as an error of that view would.
void write_synthetic_scene(const std::filesystem::path& dir, const SyntheticSceneOptions& options,
                           const std::function<void(int, int)>& progress = {});

}  // namespace d2gs
