#include "d2gs/demo/synthetic_scene.hpp"

#include <omp.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <exception>
#include <limits>
#include <regex>
#include <string>

#include <fmt/format.h>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/interrupt.hpp"
#include "d2gs/core/npy.hpp"
#include "d2gs/core/random.hpp"
#include "d2gs/model/ply.hpp"

namespace d2gs {
namespace fs = std::filesystem;
using glm::dvec3;
using glm::vec3;

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kGroundY = 1.2;     // the ground plane y = 1.2 (y points down)
constexpr double kBackdropZ = 40.0;  // the backdrop plane z = 40
constexpr double kAmbient = 0.4;
constexpr double kDiffuse = 0.7;
constexpr double kRayEpsilon = 1e-6;

// ---- deterministic randomness ----------------------------------------------------------------------
// The layout draws from one SplitMix64 stream (core/random.hpp); textures hash lattice points.

std::uint32_t hash3(std::int64_t x, std::int64_t y, std::int64_t z, std::uint32_t seed) {
  std::uint64_t h = seed * 0x9E3779B97F4A7C15ull;
  h ^= static_cast<std::uint64_t>(x) * 0xD6E8FEB86659FD93ull;
  h = std::rotl(h, 29) * 0xBF58476D1CE4E5B9ull;
  h ^= static_cast<std::uint64_t>(y) * 0x9E3779B97F4A7C15ull;
  h = std::rotl(h, 31) * 0x94D049BB133111EBull;
  h ^= static_cast<std::uint64_t>(z) * 0xC2B2AE3D27D4EB4Full;
  h ^= h >> 32;
  h *= 0xD6E8FEB86659FD93ull;
  h ^= h >> 32;
  return static_cast<std::uint32_t>(h);
}

double unit(std::uint32_t h) { return static_cast<double>(h) * (1.0 / 4294967296.0); }

// Value noise in [0, 1]: hashed lattice values, smoothstep-interpolated.
double value_noise(const dvec3& p, std::uint32_t seed) {
  const dvec3 f = glm::floor(p);
  const dvec3 t = p - f;
  const dvec3 w = t * t * (3.0 - 2.0 * t);
  const auto ix = static_cast<std::int64_t>(f.x), iy = static_cast<std::int64_t>(f.y), iz = static_cast<std::int64_t>(f.z);
  double c[2][2][2];
  for (int a = 0; a < 2; ++a)
    for (int b = 0; b < 2; ++b)
      for (int d = 0; d < 2; ++d) c[a][b][d] = unit(hash3(ix + a, iy + b, iz + d, seed));
  const auto lerp = [](double u, double v, double s) { return u + (v - u) * s; };
  const double x00 = lerp(c[0][0][0], c[1][0][0], w.x), x10 = lerp(c[0][1][0], c[1][1][0], w.x);
  const double x01 = lerp(c[0][0][1], c[1][0][1], w.x), x11 = lerp(c[0][1][1], c[1][1][1], w.x);
  return lerp(lerp(x00, x10, w.y), lerp(x01, x11, w.y), w.z);
}

double fbm(const dvec3& p, std::uint32_t seed, int octaves) {
  double sum = 0.0, amplitude = 1.0, norm = 0.0, frequency = 1.0;
  for (int o = 0; o < octaves; ++o) {
    sum += amplitude * value_noise(p * frequency, seed + static_cast<std::uint32_t>(o) * 101u);
    norm += amplitude;
    amplitude *= 0.5;
    frequency *= 2.03;
  }
  return sum / norm;
}

vec3 hsv(double h, double s, double v) {
  h = h - std::floor(h);
  const double i = std::floor(h * 6.0);
  const double f = h * 6.0 - i;
  const double p = v * (1 - s), q = v * (1 - s * f), t = v * (1 - s * (1 - f));
  dvec3 rgb;
  switch (static_cast<int>(i) % 6) {
    case 0: rgb = {v, t, p}; break;
    case 1: rgb = {q, v, p}; break;
    case 2: rgb = {p, v, t}; break;
    case 3: rgb = {p, q, v}; break;
    case 4: rgb = {t, p, v}; break;
    default: rgb = {v, p, q}; break;
  }
  return vec3(rgb);
}

glm::dmat3 rotation_y(double angle) {
  const double c = std::cos(angle), s = std::sin(angle);
  // Columns of the local-to-world rotation about the (down-pointing) y axis.
  return glm::dmat3(dvec3(c, 0, -s), dvec3(0, 1, 0), dvec3(s, 0, c));
}

glm::dmat3 rotation_xz(double ax, double az) {
  const double cx = std::cos(ax), sx = std::sin(ax), cz = std::cos(az), sz = std::sin(az);
  const glm::dmat3 rx(dvec3(1, 0, 0), dvec3(0, cx, sx), dvec3(0, -sx, cx));
  const glm::dmat3 rz(dvec3(cz, sz, 0), dvec3(-sz, cz, 0), dvec3(0, 0, 1));
  return rz * rx;
}

// 8-bit value as write_image stores it.
std::uint8_t to_byte(float v) { return static_cast<std::uint8_t>(std::lround(std::clamp(v, 0.0f, 1.0f) * 255.0f)); }

// ---- objects ---------------------------------------------------------------------------------------

enum class Shape { Plane, Sphere, Box };
enum class Texture { Checker, Stripes, Noise, Patches };

const char* to_string(Shape s) {
  switch (s) {
    case Shape::Plane: return "plane";
    case Shape::Sphere: return "sphere";
    case Shape::Box: return "box";
  }
  return "?";
}
const char* to_string(Texture t) {
  switch (t) {
    case Texture::Checker: return "checker";
    case Texture::Stripes: return "stripes";
    case Texture::Noise: return "noise";
    case Texture::Patches: return "patches";
  }
  return "?";
}

}  // namespace

struct SyntheticScene::Object {
  std::string name;
  Shape shape = Shape::Sphere;
  dvec3 center{0.0};          // plane: a point on it
  dvec3 normal{0.0, -1.0, 0.0};  // plane only
  double radius = 1.0;        // sphere
  dvec3 half{1.0};            // box half extents (local axes)
  double yaw = 0.0;           // box: rotation about the vertical axis (radians)
  glm::dmat3 local_to_world{1.0};  // texture and box frame
  glm::dmat3 world_to_local{1.0};
  double bound_radius = 0.0;  // spheres and boxes: radius of a sphere around `center` holding them
  Texture texture = Texture::Checker;
  std::array<vec3, 3> colors{};
  double frequency = 1.0;     // texture cells per world unit
  std::uint32_t texture_seed = 0;
  bool casts_shadow = true;
  bool receives_shadow = true;
};

namespace {

using Object = SyntheticScene::Object;

// Ray parameter of the first intersection with t > kRayEpsilon, or +inf; normal in world (not flipped).
double intersect_object(const Object& o, const dvec3& origin, const dvec3& dir, dvec3* normal) {
  constexpr double inf = std::numeric_limits<double>::infinity();
  switch (o.shape) {
    case Shape::Plane: {
      const double denom = glm::dot(o.normal, dir);
      if (std::abs(denom) < 1e-12) return inf;
      const double t = glm::dot(o.normal, o.center - origin) / denom;
      if (t <= kRayEpsilon) return inf;
      if (normal) *normal = o.normal;
      return t;
    }
    case Shape::Sphere: {
      const dvec3 oc = origin - o.center;
      const double a = glm::dot(dir, dir);
      const double b = glm::dot(oc, dir);
      const double c = glm::dot(oc, oc) - o.radius * o.radius;
      const double disc = b * b - a * c;
      if (disc < 0) return inf;
      const double sq = std::sqrt(disc);
      double t = (-b - sq) / a;
      if (t <= kRayEpsilon) t = (-b + sq) / a;
      if (t <= kRayEpsilon) return inf;
      if (normal) *normal = (origin + t * dir - o.center) / o.radius;
      return t;
    }
    case Shape::Box: {
      const dvec3 ol = o.world_to_local * (origin - o.center);
      const dvec3 dl = o.world_to_local * dir;
      double t_near = -inf, t_far = inf;
      int axis = 0;
      for (int i = 0; i < 3; ++i) {
        if (std::abs(dl[i]) < 1e-15) {
          if (std::abs(ol[i]) > o.half[i]) return inf;
          continue;
        }
        double t1 = (-o.half[i] - ol[i]) / dl[i];
        double t2 = (o.half[i] - ol[i]) / dl[i];
        if (t1 > t2) std::swap(t1, t2);
        if (t1 > t_near) {
          t_near = t1;
          axis = i;
        }
        t_far = std::min(t_far, t2);
        if (t_near > t_far) return inf;
      }
      if (t_near <= kRayEpsilon) return inf;  // cameras are never inside a box
      if (normal) {
        dvec3 nl(0.0);
        nl[axis] = dl[axis] > 0 ? -1.0 : 1.0;
        *normal = o.local_to_world * nl;
      }
      return t_near;
    }
  }
  return inf;
}

// Albedo of object `o` at world point p. `footprint`: world size of a pixel at p; texture detail finer
// than a pixel fades to its mean (a cheap pre-filter against moire on the grazing ground).
vec3 albedo(const Object& o, const dvec3& p, double footprint) {
  dvec3 q = glm::transpose(o.local_to_world) * (p - o.center);
  if (o.shape == Shape::Plane) q.z = 0.37;  // planes: local x, y span the plane, z is its normal
  else q += dvec3(0.37, 0.41, 0.43);        // keep cell borders off box faces
  const double s = o.frequency;
  const double detail = std::clamp((0.75 - footprint * s) / 0.5, 0.0, 1.0);
  const vec3 mean = (o.colors[0] + o.colors[1] + o.colors[2]) / 3.0f;
  const auto fade = [&](const vec3& c) { return glm::mix(mean, c, static_cast<float>(detail)); };
  switch (o.texture) {
    case Texture::Checker: {
      const dvec3 c = glm::floor(q * s);
      const auto parity = (static_cast<std::int64_t>(c.x) + static_cast<std::int64_t>(c.y) + static_cast<std::int64_t>(c.z)) & 1;
      const vec3 base = fade(parity ? o.colors[0] : o.colors[1]);
      const double n = fbm(q * (0.5 * s), o.texture_seed, 2);
      return base * static_cast<float>(0.75 + 0.5 * n) + o.colors[2] * static_cast<float>(0.1 * detail * (n > 0.6));
    }
    case Texture::Stripes: {
      const double v = q.y * s + 0.8 * fbm(q * (0.6 * s), o.texture_seed, 2);
      const double band = std::floor(v);
      const auto index = static_cast<std::size_t>(((static_cast<std::int64_t>(band) % 3) + 3) % 3);
      vec3 c = o.colors[index];
      if (v - band < 0.1) c *= 0.3f;  // thin dark lines between the bands
      return fade(c) * static_cast<float>(0.85 + 0.3 * value_noise(q * (3.0 * s), o.texture_seed + 7));
    }
    case Texture::Noise: {
      const double n = fbm(q * s, o.texture_seed, 4);
      const double t = std::clamp((n - 0.25) / 0.5, 0.0, 1.0);
      const vec3 c = t < 0.5 ? glm::mix(o.colors[0], o.colors[1], static_cast<float>(t * 2.0))
                             : glm::mix(o.colors[1], o.colors[2], static_cast<float>(t * 2.0 - 1.0));
      // Sparse bright speckles: point-like features at every scale.
      const double speck = value_noise(q * (6.0 * s), o.texture_seed + 13);
      return speck > 0.8 ? fade(glm::mix(c, vec3(1.0f), 0.6f)) : c;
    }
    case Texture::Patches: {
      const dvec3 c = glm::floor(q * s);
      const dvec3 f = q * s - c;
      const std::uint32_t h = hash3(static_cast<std::int64_t>(c.x), static_cast<std::int64_t>(c.y),
                                    static_cast<std::int64_t>(c.z), o.texture_seed);
      vec3 col = o.colors[h % 3] * static_cast<float>(0.55 + 0.45 * unit(h * 2654435761u));
      const bool grout = (o.shape == Shape::Plane) ? (f.x < 0.07 || f.y < 0.07)
                                                   : (f.x < 0.07 || f.y < 0.07 || f.z < 0.07);
      if (grout) col = vec3(0.12f, 0.11f, 0.1f);
      return fade(col);
    }
  }
  return mean;
}

}  // namespace

SyntheticScene::~SyntheticScene() = default;
SyntheticScene::SyntheticScene(const SyntheticScene&) = default;
SyntheticScene& SyntheticScene::operator=(const SyntheticScene&) = default;

void validate(const SyntheticSceneOptions& o) {
  if (o.width < 16 || o.width > 8192) fail("synthetic scene: width {} is outside 16..8192", o.width);
  if (o.height < 16 || o.height > 8192) fail("synthetic scene: height {} is outside 16..8192", o.height);
  if (o.views < 2 || o.views > 1000) fail("synthetic scene: views {} is outside 2..1000", o.views);
  if (o.supersample < 1 || o.supersample > 8) fail("synthetic scene: supersample {} is outside 1..8", o.supersample);
  if (!(o.focal >= 0.0) || !std::isfinite(o.focal)) fail("synthetic scene: focal length {} must be >= 0 (0: default)", o.focal);
  if (o.points < 0 || o.points > 10'000'000) fail("synthetic scene: points {} is outside 0..10000000", o.points);
}

SyntheticScene::SyntheticScene(const SyntheticSceneOptions& options) : options_(options) {
  validate(options_);
  SplitMix64 rng(options_.seed ^ 0xD25C5EED5EEDull);
  const auto palette = [&](double hue, double saturation = 0.65) {
    std::array<vec3, 3> c;
    for (int i = 0; i < 3; ++i)
      c[static_cast<std::size_t>(i)] = hsv(hue + 0.31 * i + rng.uniform(-0.05, 0.05), saturation + rng.uniform(-0.2, 0.2),
                                           rng.uniform(0.5, 0.95));
    return c;
  };
  const auto add = [&](Object o) {
    o.texture_seed = static_cast<std::uint32_t>(rng.next_u64() >> 32);
    o.world_to_local = glm::transpose(o.local_to_world);
    o.bound_radius = o.shape == Shape::Sphere ? o.radius : o.shape == Shape::Box ? glm::length(o.half) : 0.0;
    objects_.push_back(std::move(o));
  };
  // Jitter: sideways and in depth proportionally to the distance, size by +-10 %.
  const auto jitter = [&](dvec3 c, double size_scale_range) {
    c.x += rng.uniform(-1, 1) * 0.04 * c.z;
    c.z *= 1.0 + rng.uniform(-1, 1) * 0.05;
    return std::pair{c, 1.0 + rng.uniform(-1, 1) * size_scale_range};
  };
  const auto sphere = [&](const char* name, dvec3 c, double r, Texture tex, double freq) {
    Object o;
    o.name = name;
    o.shape = Shape::Sphere;
    const auto [jc, k] = jitter(c, 0.1);
    o.radius = r * k;
    o.center = jc;
    o.center.y = kGroundY - o.radius;  // resting on the ground
    o.local_to_world = rotation_xz(rng.uniform(-0.6, 0.6), rng.uniform(-0.6, 0.6));
    o.texture = tex;
    o.frequency = freq;
    o.colors = palette(rng.uniform());
    add(o);
  };
  const auto box = [&](const char* name, dvec3 c, dvec3 half, double yaw_degrees, Texture tex, double freq) {
    Object o;
    o.name = name;
    o.shape = Shape::Box;
    const auto [jc, k] = jitter(c, 0.1);
    o.half = half * k;
    o.center = jc;
    o.center.y = kGroundY - o.half.y;
    o.yaw = (yaw_degrees + rng.uniform(-12, 12)) * kPi / 180.0;
    o.local_to_world = rotation_y(o.yaw);
    o.texture = tex;
    o.frequency = freq;
    o.colors = palette(rng.uniform());
    add(o);
  };
  {
    Object ground;
    ground.name = "ground";
    ground.shape = Shape::Plane;
    ground.center = dvec3(0, kGroundY, 0);
    ground.normal = dvec3(0, -1, 0);
    // Local x = world x, local y = world z, local z = the normal.
    ground.local_to_world = glm::dmat3(dvec3(1, 0, 0), dvec3(0, 0, 1), dvec3(0, -1, 0));
    ground.texture = Texture::Checker;
    ground.frequency = 1.25;
    ground.colors = palette(rng.uniform(), 0.45);
    ground.casts_shadow = false;
    add(ground);
    Object backdrop;
    backdrop.name = "backdrop";
    backdrop.shape = Shape::Plane;
    backdrop.center = dvec3(0, 0, kBackdropZ);
    backdrop.normal = dvec3(0, 0, -1);
    backdrop.local_to_world = glm::dmat3(dvec3(1, 0, 0), dvec3(0, 1, 0), dvec3(0, 0, -1));
    backdrop.texture = Texture::Patches;
    backdrop.frequency = 0.28;
    backdrop.colors = palette(rng.uniform(), 0.35);
    backdrop.casts_shadow = false;
    backdrop.receives_shadow = false;  // too far for the objects' shadows to matter
    add(backdrop);
  }
  // Near field (2.5-4 units), middle (5-13), far (16-25).
  sphere("near sphere", {-0.85, 0, 3.0}, 0.5, Texture::Stripes, 5.0);
  box("near box", {0.95, 0, 3.6}, {0.4, 0.4, 0.4}, 35, Texture::Patches, 5.0);
  box("panel", {0.15, 0, 5.5}, {0.8, 0.75, 0.04}, -10, Texture::Checker, 4.0);
  sphere("middle sphere", {1.9, 0, 7.5}, 1.0, Texture::Checker, 2.5);
  box("pillar", {-2.0, 0, 9.0}, {0.6, 1.5, 0.6}, 25, Texture::Noise, 1.5);
  sphere("small sphere", {0.6, 0, 13.0}, 0.6, Texture::Stripes, 3.0);
  sphere("far sphere", {-7.0, 0, 18.0}, 2.5, Texture::Noise, 0.8);
  box("far box", {5.5, 0, 24.0}, {2.5, 2.5, 2.5}, 40, Texture::Patches, 1.0);

  to_light_ = glm::normalize(dvec3(-0.45 + rng.uniform(-0.1, 0.1), -1.0, -0.55 + rng.uniform(-0.1, 0.1)));

  // Cameras: a grid in the plane z = 0 in raster order (row by row, left to right, top row first), all
  // looking at the focus point. Raster order spreads the sparse-view training picks of method.md §3
  // (for 20 views: images 1, 10, 19) over the grid: top, left and bottom-right.
  focus_ = dvec3(rng.uniform(-0.2, 0.2), 0.1 + rng.uniform(-0.1, 0.1), 9.0 + rng.uniform(-0.5, 0.5));
  const int n = options_.views;
  const int cols = std::max(1, static_cast<int>(std::lround(std::sqrt(n * 5.0 / 4.0))));
  const int rows = (n + cols - 1) / cols;
  const double f = options_.focal > 0 ? options_.focal : 407.566 * options_.width / 504.0;
  for (int k = 0; k < n; ++k) {
    const int r = k / cols;
    const int c = k % cols;
    const double x = cols > 1 ? -0.5 + 1.0 * c / (cols - 1) : 0.0;
    const double y = rows > 1 ? -0.3 + 0.6 * r / (rows - 1) : 0.0;
    const dvec3 center(x + rng.uniform(-0.03, 0.03), y + rng.uniform(-0.03, 0.03), rng.uniform(-0.05, 0.05));
    const dvec3 forward = glm::normalize(focus_ - center);
    const dvec3 right = glm::normalize(glm::cross(dvec3(0, 1, 0), forward));
    const dvec3 down = glm::cross(forward, right);
    Camera cam;
    cam.image_name = fmt::format("image{:03d}.png", k);
    cam.image_path = fs::path("images") / cam.image_name;
    cam.width = options_.width;
    cam.height = options_.height;
    cam.fx = cam.fy = f;
    cam.cx = 0.5 * options_.width;
    cam.cy = 0.5 * options_.height;
    const glm::dmat3 c2w(right, down, forward);
    cam.R_world_to_cam = glm::transpose(c2w);
    cam.t_world_to_cam = -(cam.R_world_to_cam * center);
    cameras_.push_back(cam);
  }
}

SyntheticHit SyntheticScene::intersect(const dvec3& origin, const dvec3& direction, const ScreenRect* rects,
                                       double px, double py) const {
  SyntheticHit best;
  double best_t = std::numeric_limits<double>::infinity();
  dvec3 normal;
  for (std::size_t i = 0; i < objects_.size(); ++i) {
    if (rects && !rects[i].contains(px, py)) continue;
    dvec3 n;
    const double t = intersect_object(objects_[i], origin, direction, &n);
    if (t < best_t) {
      best_t = t;
      normal = n;
      best.object = static_cast<int>(i);
    }
  }
  if (best.object < 0) return best;
  best.hit = true;
  best.position = origin + best_t * direction;
  best.normal = glm::dot(normal, direction) > 0 ? -normal : normal;
  best.depth = best_t;  // caller's direction has unit view-space z
  return best;
}

bool SyntheticScene::occluded(const dvec3& origin, const dvec3& direction) const {
  // `direction` is a unit vector: reject by the bounding sphere first.
  for (const auto& o : objects_) {
    if (!o.casts_shadow) continue;
    const dvec3 oc = o.center - origin;
    const double along = glm::dot(oc, direction);
    if (along < -o.bound_radius) continue;
    if (glm::dot(oc, oc) - along * along > o.bound_radius * o.bound_radius) continue;
    if (std::isfinite(intersect_object(o, origin, direction, nullptr))) return true;
  }
  return false;
}

vec3 SyntheticScene::shade(const SyntheticHit& hit, const dvec3& direction, double footprint) const {
  const Object& o = objects_[static_cast<std::size_t>(hit.object)];
  const double cos_view = std::abs(glm::dot(hit.normal, direction)) / glm::length(direction);
  const vec3 a = albedo(o, hit.position, footprint / std::max(cos_view, 0.05));
  double light = kAmbient;
  const double lambert = glm::dot(hit.normal, to_light_);
  if (lambert > 0 && !(o.receives_shadow && occluded(hit.position + 1e-5 * hit.normal, to_light_)))
    light += kDiffuse * lambert;
  return glm::clamp(a * static_cast<float>(light), vec3(0.0f), vec3(1.0f));
}

SyntheticScene::View SyntheticScene::prepare(const Camera& camera, bool cull) const {
  View v;
  v.origin = camera.center_world();
  v.cam_to_world = camera.R_cam_to_world();
  v.fx = camera.fx;
  v.fy = camera.fy;
  v.cx = camera.cx;
  v.cy = camera.cy;
  if (!cull) return v;
  v.rects.resize(objects_.size());
  for (std::size_t i = 0; i < objects_.size(); ++i) {
    const Object& o = objects_[i];
    if (o.shape == Shape::Plane) continue;
    // Exact extent of the projected bounding sphere along x and y: the tangent planes through the
    // camera centre that contain the other image axis (Mara & McGuire 2013), plus a 2-pixel margin.
    const dvec3 c = camera.R_world_to_cam * o.center + camera.t_world_to_cam;
    const double r = o.bound_radius * (1.0 + 1e-9) + 1e-9;
    if (c.z - r < 1e-3 * std::max(1.0, r)) continue;  // reaches the camera plane: never culled
    const auto extent = [&](double a, double f, double centre, double& lo, double& hi) {
      const double denom = c.z * c.z - r * r;
      const double root = r * std::sqrt(std::max(0.0, a * a + c.z * c.z - r * r));
      lo = f * (a * c.z - root) / denom + centre - 2.0;
      hi = f * (a * c.z + root) / denom + centre + 2.0;
    };
    extent(c.x, camera.fx, camera.cx, v.rects[i].x0, v.rects[i].x1);
    extent(c.y, camera.fy, camera.cy, v.rects[i].y0, v.rects[i].y1);
  }
  return v;
}

SyntheticHit SyntheticScene::trace(const View& view, double px, double py, bool with_colour) const {
  const dvec3 dir = view.cam_to_world * dvec3((px - view.cx) / view.fx, (py - view.cy) / view.fy, 1.0);
  SyntheticHit hit = intersect(view.origin, dir, view.rects.empty() ? nullptr : view.rects.data(), px, py);
  if (hit.hit && with_colour) hit.color = shade(hit, dir, hit.depth / view.fx);
  return hit;
}

SyntheticHit SyntheticScene::trace(const Camera& camera, double px, double py) const {
  return trace(prepare(camera, false), px, py, true);
}

double SyntheticScene::trace_depth(const Camera& camera, int x, int y) const {
  const SyntheticHit hit = trace(prepare(camera, false), x + 0.5, y + 0.5, false);
  return hit.hit ? hit.depth : std::numeric_limits<double>::infinity();
}

Image SyntheticScene::render(const Camera& camera) const {
  // Adaptive supersampling: one ray through every pixel centre first; pixels whose 3x3 neighbourhood
  // shows another object or a colour step above kEdge get the full s x s grid (box filter).
  constexpr float kEdge = 0.04f;
  const int w = camera.width, h = camera.height;
  const View view = prepare(camera, true);
  const int s = options_.supersample;
  std::vector<vec3> centre(static_cast<std::size_t>(w) * static_cast<std::size_t>(h));
  std::vector<int> object(centre.size());
  const auto at = [w](int x, int y) { return static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x); };
#pragma omp parallel for schedule(dynamic, 8) if (!omp_in_parallel())
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const SyntheticHit hit = trace(view, x + 0.5, y + 0.5, true);
      centre[at(x, y)] = hit.color;
      object[at(x, y)] = hit.object;
    }
  Image image(w, h, 3);
  const float weight = 1.0f / static_cast<float>(s * s);
#pragma omp parallel for schedule(dynamic, 4) if (!omp_in_parallel())
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const vec3 c = centre[at(x, y)];
      bool edge = false;
      for (int dy = -1; dy <= 1 && !edge && s > 1; ++dy)
        for (int dx = -1; dx <= 1 && !edge; ++dx) {
          const int nx = std::clamp(x + dx, 0, w - 1), ny = std::clamp(y + dy, 0, h - 1);
          const vec3 d = glm::abs(centre[at(nx, ny)] - c);
          edge = object[at(nx, ny)] != object[at(x, y)] || std::max({d.x, d.y, d.z}) > kEdge;
        }
      vec3 colour = c;
      if (edge) {
        vec3 sum(0.0f);
        for (int j = 0; j < s; ++j)
          for (int i = 0; i < s; ++i)
            sum += (s % 2 == 1 && 2 * i + 1 == s && 2 * j + 1 == s)
                       ? c  // the centre sample of an odd grid is the ray traced above
                       : trace(view, x + (i + 0.5) / s, y + (j + 0.5) / s, true).color;
        colour = sum * weight;
      }
      for (int k = 0; k < 3; ++k) image.at(x, y, k) = colour[k];
    }
  return image;
}

std::vector<float> SyntheticScene::depth_map(const Camera& camera) const {
  std::vector<float> depth(static_cast<std::size_t>(camera.width) * static_cast<std::size_t>(camera.height));
  const View view = prepare(camera, true);
#pragma omp parallel for schedule(dynamic, 8) if (!omp_in_parallel())
  for (int y = 0; y < camera.height; ++y)
    for (int x = 0; x < camera.width; ++x) {
      const SyntheticHit hit = trace(view, x + 0.5, y + 0.5, false);
      depth[static_cast<std::size_t>(y) * static_cast<std::size_t>(camera.width) + static_cast<std::size_t>(x)] =
          hit.hit ? static_cast<float>(hit.depth) : std::numeric_limits<float>::infinity();
    }
  return depth;
}

PointCloud SyntheticScene::sample_points(int view, int count) const {
  PointCloud cloud;
  if (count <= 0) return cloud;
  const Camera& cam = cameras_.at(static_cast<std::size_t>(view));
  const View prepared = prepare(cam, true);
  const int gx = std::max(1, static_cast<int>(std::lround(std::sqrt(count * static_cast<double>(cam.width) / cam.height))));
  const int gy = std::max(1, (count + gx - 1) / gx);
  const auto seed = static_cast<std::uint32_t>(options_.seed ^ (options_.seed >> 32)) + 0x5EEDu;
  for (int j = 0; j < gy; ++j)
    for (int i = 0; i < gx; ++i) {
      if (static_cast<int>(cloud.size()) >= count) return cloud;
      const double u = unit(hash3(view, i, j, seed)), v = unit(hash3(view, i, j, seed + 1));
      const double px = (i + u) * cam.width / gx, py = (j + v) * cam.height / gy;
      const SyntheticHit hit = trace(prepared, px, py, true);
      if (!hit.hit) continue;
      cloud.positions.emplace_back(vec3(hit.position));
      cloud.colors.emplace_back(to_byte(hit.color.x), to_byte(hit.color.y), to_byte(hit.color.z));
    }
  return cloud;
}

nlohmann::json SyntheticScene::describe() const {
  using nlohmann::json;
  const auto v3 = [](const auto& v) { return json::array({v.x, v.y, v.z}); };
  json objects = json::array();
  for (const auto& o : objects_) {
    json j{{"name", o.name}, {"shape", to_string(o.shape)}, {"texture", to_string(o.texture)},
           {"texture_frequency", o.frequency}, {"casts_shadow", o.casts_shadow}};
    json colors = json::array();
    for (const auto& c : o.colors) colors.push_back(v3(c));
    j["colors"] = colors;
    switch (o.shape) {
      case Shape::Plane: j["point"] = v3(o.center); j["normal"] = v3(o.normal); break;
      case Shape::Sphere: j["center"] = v3(o.center); j["radius"] = o.radius; break;
      case Shape::Box:
        j["center"] = v3(o.center);
        j["half_extents"] = v3(o.half);
        j["yaw_degrees"] = o.yaw * 180.0 / kPi;
        break;
    }
    objects.push_back(j);
  }
  json cams = json::array();
  for (const auto& c : cameras_) {
    json r = json::array();
    for (int i = 0; i < 3; ++i) r.push_back(json::array({c.R_world_to_cam[0][i], c.R_world_to_cam[1][i], c.R_world_to_cam[2][i]}));
    cams.push_back({{"image", c.image_name}, {"center", v3(c.center_world())}, {"R_world_to_cam", r},
                    {"fx", c.fx}, {"fy", c.fy}, {"cx", c.cx}, {"cy", c.cy}});
  }
  return json{
      {"generator", kSyntheticSceneGenerator},
      {"seed", options_.seed},
      {"width", options_.width},
      {"height", options_.height},
      {"views", options_.views},
      {"supersample", options_.supersample},
      {"points_requested", options_.points},
      {"world_frame", "x right, y down, z forward (away from the cameras); ground plane y = 1.2, backdrop plane z = 40"},
      {"camera_layout", "grid in the plane z = 0 in raster order (x in [-0.5, 0.5], y in [-0.3, 0.3], jittered), "
                        "every camera looking at the focus point; OpenCV axes (x right, y down, z forward)"},
      {"focus_point", v3(focus_)},
      {"light", {{"direction_to_light", v3(to_light_)}, {"ambient", kAmbient}, {"diffuse", kDiffuse},
                 {"model", "Lambertian, hard shadows cast by spheres and boxes"}}},
      {"objects", objects},
      {"cameras", cams},
  };
}

std::vector<Camera> synthetic_scene_cameras(const SyntheticSceneOptions& options) {
  return SyntheticScene(options).cameras();
}

// ---- writing ---------------------------------------------------------------------------------------

namespace {

nlohmann::json read_scene_json(const fs::path& dir) {
  try {
    return nlohmann::json::parse(read_file(dir / "scene.json"));
  } catch (const std::exception&) {
    return nlohmann::json();
  }
}

// True when `dir` holds nothing, or nothing but the lock file of the demo writing into it.
bool holds_only_the_demo_lock(const fs::path& dir) {
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec))
    if (it->path().filename() != kSyntheticSceneLock) return false;
  return !ec;
}

// Removes the files of a previous synthetic scene that the new one will not replace: images and depth
// maps of views >= `views`, and temporaries left by an interrupted run. Nothing else is touched.
void remove_stale_files(const fs::path& dir, int views) {
  static const std::regex own(R"((image)(\d+)\.(png|npy))");
  static const std::regex temporary(R"(\.(image\d+|scene|poses_bounds|points3D)\.tmp\d+-\d+\.(png|npy|json|ply))");
  for (const auto* sub : {"images", "depth", ""}) {
    const fs::path folder = dir / sub;
    std::error_code ec;
    if (!fs::is_directory(folder, ec)) continue;
    std::vector<fs::path> doomed;
    for (fs::directory_iterator it(folder, ec), end; !ec && it != end; it.increment(ec)) {
      if (!it->is_regular_file(ec)) continue;
      const std::string name = it->path().filename().string();
      std::smatch m;
      if (std::regex_match(name, temporary)) doomed.push_back(it->path());
      else if (*sub && std::regex_match(name, m, own) && (std::string(sub) == "images") == (m[3] == "png") &&
               std::stol(m[2]) >= views)
        doomed.push_back(it->path());
    }
    for (const auto& p : doomed) fs::remove(p, ec);
  }
}

}  // namespace

bool is_synthetic_scene(const fs::path& dir) {
  const auto j = read_scene_json(dir);
  return j.is_object() && j.contains("generator") && j["generator"] == kSyntheticSceneGenerator;
}

void write_synthetic_scene(const fs::path& dir, const SyntheticSceneOptions& options,
                           const std::function<void(int, int)>& progress) {
  validate(options);
  std::error_code ec;
  if (fs::exists(dir, ec)) {
    if (!fs::is_directory(dir, ec)) fail_file(dir, "exists and is not a folder; refusing to write a scene there");
    if (!holds_only_the_demo_lock(dir) && !is_synthetic_scene(dir))
      fail_file(dir, "folder is not empty and holds no synthetic scene (no scene.json of d2gs); refusing to "
                     "overwrite it: choose another folder");
    remove_stale_files(dir, options.views);
  }
  fs::create_directories(dir / "images", ec);
  if (ec) fail_file(dir / "images", "cannot create folder: {}", ec.message());
  fs::create_directories(dir / "depth", ec);
  if (ec) fail_file(dir / "depth", "cannot create folder: {}", ec.message());

  const SyntheticScene scene(options);
  nlohmann::json description = scene.describe();
  description["complete"] = false;  // marks the folder as ours while the views are written
  write_file_atomic(dir / "scene.json", description.dump(2) + "\n");
  // The poses of an earlier scene go before any view is replaced and come back last: a rewrite that fails
  // or is interrupted part-way leaves a folder that no loader takes for a scene (old and new views mixed).
  fs::remove(dir / "poses_bounds.npy", ec);
  fs::remove(dir / "points3D.ply", ec);

  const auto& cams = scene.cameras();
  const int n = static_cast<int>(cams.size());
  std::vector<double> poses(static_cast<std::size_t>(n) * 17);
  std::vector<PointCloud> points(static_cast<std::size_t>(n));
  const int points_per_view = (options.points + n - 1) / n;
  std::exception_ptr error;
  int done = 0;
#pragma omp parallel for schedule(dynamic, 1)
  for (int k = 0; k < n; ++k) {
    try {
      check_interrupted("while writing the demo scene");  // caught below as any error of view k
      bool skip = false;
#pragma omp critical(d2gs_synthetic_error)
      skip = static_cast<bool>(error);
      if (skip) continue;
      const Camera& cam = cams[static_cast<std::size_t>(k)];
      write_image(dir / cam.image_path, scene.render(cam));
      const std::vector<float> depth = scene.depth_map(cam);
      write_npy_f32(dir / "depth" / fmt::format("image{:03d}.npy", k),
                    {static_cast<std::size_t>(cam.height), static_cast<std::size_t>(cam.width)}, depth);
      points[static_cast<std::size_t>(k)] = scene.sample_points(k, points_per_view);
      // LLFF row: 3x5 [down, right, back | centre | (H, W, f)] read row-major, then near, far.
      const glm::dmat3 c2w = cam.R_cam_to_world();
      const dvec3 llff_cols[3] = {c2w[1], c2w[0], -c2w[2]};
      const dvec3 center = cam.center_world();
      const double hwf[3] = {static_cast<double>(cam.height), static_cast<double>(cam.width), cam.fx};
      double* row = poses.data() + static_cast<std::size_t>(k) * 17;
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) row[r * 5 + c] = llff_cols[c][r];
        row[r * 5 + 3] = center[r];
        row[r * 5 + 4] = hwf[r];
      }
      const auto [lo, hi] = std::minmax_element(depth.begin(), depth.end());
      row[15] = *lo;
      row[16] = *hi;
      // No exception may leave an OpenMP critical section: the callback's is taken out of it, then thrown
      // here as an error of view k.
      std::exception_ptr failed;
#pragma omp critical(d2gs_synthetic_progress)
      {
        ++done;
        if (progress) try {
            progress(done, n);
          } catch (...) {
            failed = std::current_exception();
          }
      }
      if (failed) std::rethrow_exception(failed);
    } catch (...) {
#pragma omp critical(d2gs_synthetic_error)
      if (!error) error = std::current_exception();
    }
  }
  if (error) std::rethrow_exception(error);

  write_npy_f64(dir / "poses_bounds.npy", {static_cast<std::size_t>(n), 17}, poses);
  PointCloud all;
  for (const auto& p : points) {
    all.positions.insert(all.positions.end(), p.positions.begin(), p.positions.end());
    all.colors.insert(all.colors.end(), p.colors.begin(), p.colors.end());
  }
  write_point_cloud_ply(dir / "points3D.ply", all);
  description["complete"] = true;
  description["points"] = all.size();
  description["files"] = {{"images", "images/image000.png ... (RGB, 8-bit)"},
                          {"poses_bounds", "poses_bounds.npy (N x 17 float64, LLFF convention)"},
                          {"depth", "depth/image000.npy ... (float32 H x W, view-space z at pixel centres)"},
                          {"points", "points3D.ply (x y z nx ny nz red green blue; oracle: sampled from all views)"}};
  write_file_atomic(dir / "scene.json", description.dump(2) + "\n");
}

}  // namespace d2gs
