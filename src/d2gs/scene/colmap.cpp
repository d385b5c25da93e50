#include "d2gs/scene/colmap.hpp"

#include <algorithm>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstring>
#include <type_traits>
#include <unordered_map>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"

namespace d2gs {
namespace fs = std::filesystem;

static_assert(std::endian::native == std::endian::little, "COLMAP files are little-endian");

namespace {

struct ModelInfo {
  const char* name;
  int num_params;
};
constexpr ModelInfo kModels[] = {
    {"SIMPLE_PINHOLE", 3}, {"PINHOLE", 4},          {"SIMPLE_RADIAL", 4},         {"RADIAL", 5},
    {"OPENCV", 8},         {"OPENCV_FISHEYE", 8},   {"FULL_OPENCV", 12},          {"FOV", 5},
    {"SIMPLE_RADIAL_FISHEYE", 4}, {"RADIAL_FISHEYE", 5}, {"THIN_PRISM_FISHEYE", 12},
    {"RAD_TAN_THIN_PRISM_FISHEYE", 16},
};
constexpr int kNumModels = static_cast<int>(sizeof kModels / sizeof kModels[0]);
// Image names are shown in messages up to this many bytes (printable(): binary names are escaped).
constexpr std::size_t kNameBytes = 200;

// ---------------------------------------------------------------- binary reading

// Bounds-checked little-endian reader over a byte buffer; every failure names the file.
class ByteReader {
public:
  ByteReader(std::string_view bytes, const fs::path& source) : bytes_(bytes), source_(source) {}

  template <typename T>
  T read(const char* what) {
    static_assert(std::is_trivially_copyable_v<T>);
    if (remaining() < sizeof(T))
      fail_file(source_, "truncated file: {} needs {} bytes at offset {}, {} left", what, sizeof(T), pos_,
                remaining());
    T v;
    std::memcpy(&v, bytes_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    return v;
  }
  // A count followed by records of at least `min_record_bytes` each: a count the remaining bytes
  // cannot hold is rejected before anything is allocated.
  std::size_t read_count(const char* what, std::size_t min_record_bytes) {
    const auto n = read<std::uint64_t>(what);
    if (n > remaining() / min_record_bytes)
      fail_file(source_, "truncated or corrupt file: {} is {} but only {} bytes are left at offset {}", what, n,
                remaining(), pos_);
    return static_cast<std::size_t>(n);
  }
  std::string read_cstring(const char* what) {
    const auto end = bytes_.find('\0', pos_);
    if (end == std::string_view::npos)
      fail_file(source_, "truncated file: {} at offset {} has no terminating NUL", what, pos_);
    std::string s(bytes_.substr(pos_, end - pos_));
    pos_ = end + 1;
    return s;
  }
  std::size_t remaining() const { return bytes_.size() - pos_; }
  std::size_t position() const { return pos_; }
  void expect_end() const {
    if (remaining() != 0)
      fail_file(source_, "corrupt file: {} unexpected bytes after the last record (offset {})", remaining(), pos_);
  }

private:
  std::string_view bytes_;
  const fs::path& source_;
  std::size_t pos_ = 0;
};

template <typename T>
void put(std::string& out, T v) {
  static_assert(std::is_trivially_copyable_v<T>);
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  out.append(b, sizeof(T));
}

// ---------------------------------------------------------------- text reading

std::string_view trim(std::string_view s) {
  const auto ws = [](char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n'; };
  while (!s.empty() && ws(s.front())) s.remove_prefix(1);
  while (!s.empty() && ws(s.back())) s.remove_suffix(1);
  return s;
}

// Splits text into lines, keeping their 1-based numbers.
class LineReader {
public:
  explicit LineReader(std::string_view text) : text_(text) {}
  bool next(std::string_view& line) {
    if (pos_ >= text_.size()) return false;
    auto end = text_.find('\n', pos_);
    if (end == std::string_view::npos) end = text_.size();
    line = trim(text_.substr(pos_, end - pos_));
    pos_ = end + 1;
    ++number_;
    return true;
  }
  int number() const { return number_; }

private:
  std::string_view text_;
  std::size_t pos_ = 0;
  int number_ = 0;
};

// Whitespace-separated tokens of one line, parsed strictly.
class Tokens {
public:
  Tokens(std::string_view line, const fs::path& source, int line_number)
      : line_(line), source_(source), line_number_(line_number) {}

  bool empty() {
    skip();
    return pos_ >= line_.size();
  }
  std::string_view word(const char* what) {
    skip();
    if (pos_ >= line_.size()) fail_file(source_, "line {}: missing {}", line_number_, what);
    const auto start = pos_;
    while (pos_ < line_.size() && line_[pos_] != ' ' && line_[pos_] != '\t') ++pos_;
    return line_.substr(start, pos_ - start);
  }
  template <typename T>
  T number(const char* what) {
    const auto w = word(what);
    T v{};
    const char* first = w.data();
    if (!w.empty() && w.front() == '+') ++first;
    const auto [ptr, ec] = std::from_chars(first, w.data() + w.size(), v);
    if (ec != std::errc() || ptr != w.data() + w.size())
      fail_file(source_, "line {}: {} '{}' is not a valid number", line_number_, what, printable(w));
    return v;
  }
  void expect_end() {
    if (!empty()) fail_file(source_, "line {}: unexpected text '{}'", line_number_, printable(line_.substr(pos_)));
  }
  std::string_view rest() {
    skip();
    return line_.substr(pos_);
  }

private:
  void skip() {
    while (pos_ < line_.size() && (line_[pos_] == ' ' || line_[pos_] == '\t')) ++pos_;
  }
  std::string_view line_;
  const fs::path& source_;
  int line_number_;
  std::size_t pos_ = 0;
};

bool is_content(std::string_view line) { return !line.empty() && line.front() != '#'; }

fs::path pick(const fs::path& dir, const char* stem) {
  const auto bin = dir / (std::string(stem) + ".bin");
  const auto txt = dir / (std::string(stem) + ".txt");
  std::error_code ec;
  if (fs::is_regular_file(bin, ec)) return bin;
  if (fs::is_regular_file(txt, ec)) return txt;
  fail_file(dir, "no COLMAP {0}: looked for {0}.bin and {0}.txt", stem);
}

bool is_bin(const fs::path& p) { return p.extension() == ".bin"; }

}  // namespace

// ---------------------------------------------------------------- camera models

const char* colmap_model_name(int model_id) {
  return model_id >= 0 && model_id < kNumModels ? kModels[model_id].name : "UNKNOWN";
}
int colmap_model_num_params(int model_id) {
  return model_id >= 0 && model_id < kNumModels ? kModels[model_id].num_params : -1;
}
int colmap_model_id(std::string_view name) {
  for (int i = 0; i < kNumModels; ++i)
    if (name == kModels[i].name) return i;
  return -1;
}

// ---------------------------------------------------------------- binary parsers

std::vector<ColmapCamera> parse_colmap_cameras_bin(std::string_view bytes, const fs::path& source) {
  ByteReader in(bytes, source);
  const auto n = in.read_count("camera count", 24);
  std::vector<ColmapCamera> cameras;
  cameras.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    ColmapCamera c;
    c.id = in.read<std::uint32_t>("camera id");
    c.model_id = in.read<std::int32_t>("camera model");
    c.width = in.read<std::uint64_t>("camera width");
    c.height = in.read<std::uint64_t>("camera height");
    const int np = colmap_model_num_params(c.model_id);
    if (np < 0) fail_file(source, "camera {}: unknown camera model id {}", c.id, c.model_id);
    c.params.resize(static_cast<std::size_t>(np));
    for (auto& p : c.params) p = in.read<double>("camera parameter");
    cameras.push_back(std::move(c));
  }
  in.expect_end();
  return cameras;
}

std::vector<ColmapImage> parse_colmap_images_bin(std::string_view bytes, const fs::path& source) {
  ByteReader in(bytes, source);
  // image_id + qvec + tvec + camera_id + NUL + points2D count
  const auto n = in.read_count("image count", 4 + 56 + 4 + 1 + 8);
  std::vector<ColmapImage> images;
  images.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    ColmapImage im;
    im.id = in.read<std::uint32_t>("image id");
    for (auto& q : im.qvec) q = in.read<double>("image rotation");
    for (auto& t : im.tvec) t = in.read<double>("image translation");
    im.camera_id = in.read<std::uint32_t>("image camera id");
    im.name = in.read_cstring("image name");
    const auto np = in.read_count("image points2D count", 24);
    im.xys.resize(np);
    im.point3D_ids.resize(np);
    for (std::size_t k = 0; k < np; ++k) {
      im.xys[k][0] = in.read<double>("point2D x");
      im.xys[k][1] = in.read<double>("point2D y");
      im.point3D_ids[k] = in.read<std::int64_t>("point2D point3D id");
    }
    images.push_back(std::move(im));
  }
  in.expect_end();
  return images;
}

std::vector<ColmapPoint3D> parse_colmap_points3D_bin(std::string_view bytes, const fs::path& source) {
  ByteReader in(bytes, source);
  // id + xyz + rgb + error + track length
  const auto n = in.read_count("point count", 8 + 24 + 3 + 8 + 8);
  std::vector<ColmapPoint3D> points;
  points.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    ColmapPoint3D p;
    p.id = in.read<std::uint64_t>("point id");
    for (auto& x : p.xyz) x = in.read<double>("point position");
    for (auto& c : p.rgb) c = in.read<std::uint8_t>("point colour");
    p.error = in.read<double>("point error");
    const auto nt = in.read_count("point track length", 8);
    p.track.resize(nt);
    for (auto& t : p.track) {
      t.image_id = in.read<std::uint32_t>("track image id");
      t.point2D_idx = in.read<std::uint32_t>("track point2D index");
    }
    points.push_back(std::move(p));
  }
  in.expect_end();
  return points;
}

// ---------------------------------------------------------------- text parsers

std::vector<ColmapCamera> parse_colmap_cameras_txt(std::string_view text, const fs::path& source) {
  std::vector<ColmapCamera> cameras;
  LineReader lines(text);
  std::string_view line;
  while (lines.next(line)) {
    if (!is_content(line)) continue;
    Tokens t(line, source, lines.number());
    ColmapCamera c;
    c.id = t.number<std::uint32_t>("camera id");
    const auto model = t.word("camera model");
    c.model_id = colmap_model_id(model);
    if (c.model_id < 0) fail_file(source, "line {}: unknown camera model {}", lines.number(), printable(model));
    c.width = t.number<std::uint64_t>("camera width");
    c.height = t.number<std::uint64_t>("camera height");
    c.params.resize(static_cast<std::size_t>(colmap_model_num_params(c.model_id)));
    for (auto& p : c.params) p = t.number<double>("camera parameter");
    t.expect_end();
    cameras.push_back(std::move(c));
  }
  return cameras;
}

std::vector<ColmapImage> parse_colmap_images_txt(std::string_view text, const fs::path& source) {
  std::vector<ColmapImage> images;
  LineReader lines(text);
  std::string_view line;
  while (lines.next(line)) {
    if (!is_content(line)) continue;
    Tokens t(line, source, lines.number());
    ColmapImage im;
    im.id = t.number<std::uint32_t>("image id");
    for (auto& q : im.qvec) q = t.number<double>("image rotation");
    for (auto& x : im.tvec) x = t.number<double>("image translation");
    im.camera_id = t.number<std::uint32_t>("image camera id");
    // The name is the rest of the line (COLMAP names may not contain spaces, but be lenient).
    const auto name = t.rest();
    if (name.empty()) fail_file(source, "line {}: missing image name", lines.number());
    im.name = std::string(name);
    // The next line holds the observations (possibly empty), as COLMAP writes it.
    if (lines.next(line)) {
      Tokens p(line, source, lines.number());
      while (!p.empty()) {
        const double x = p.number<double>("point2D x");
        const double y = p.number<double>("point2D y");
        const auto id = p.number<std::int64_t>("point2D point3D id");
        im.xys.push_back({x, y});
        im.point3D_ids.push_back(id);
      }
    }
    images.push_back(std::move(im));
  }
  return images;
}

std::vector<ColmapPoint3D> parse_colmap_points3D_txt(std::string_view text, const fs::path& source) {
  std::vector<ColmapPoint3D> points;
  LineReader lines(text);
  std::string_view line;
  while (lines.next(line)) {
    if (!is_content(line)) continue;
    Tokens t(line, source, lines.number());
    ColmapPoint3D p;
    p.id = t.number<std::uint64_t>("point id");
    for (auto& x : p.xyz) x = t.number<double>("point position");
    for (auto& c : p.rgb) {
      const auto v = t.number<unsigned>("point colour");
      if (v > 255) fail_file(source, "line {}: colour {} is outside 0-255", lines.number(), v);
      c = static_cast<std::uint8_t>(v);
    }
    p.error = t.number<double>("point error");
    while (!t.empty()) {
      ColmapTrackElement e;
      e.image_id = t.number<std::uint32_t>("track image id");
      e.point2D_idx = t.number<std::uint32_t>("track point2D index");
      p.track.push_back(e);
    }
    points.push_back(std::move(p));
  }
  return points;
}

// ---------------------------------------------------------------- file reading

std::vector<ColmapCamera> read_colmap_cameras(const fs::path& dir) {
  const auto path = pick(dir, "cameras");
  const auto bytes = read_file(path);
  return is_bin(path) ? parse_colmap_cameras_bin(bytes, path) : parse_colmap_cameras_txt(bytes, path);
}
std::vector<ColmapImage> read_colmap_images(const fs::path& dir) {
  const auto path = pick(dir, "images");
  const auto bytes = read_file(path);
  return is_bin(path) ? parse_colmap_images_bin(bytes, path) : parse_colmap_images_txt(bytes, path);
}
std::vector<ColmapPoint3D> read_colmap_points3D(const fs::path& dir) {
  const auto path = pick(dir, "points3D");
  const auto bytes = read_file(path);
  return is_bin(path) ? parse_colmap_points3D_bin(bytes, path) : parse_colmap_points3D_txt(bytes, path);
}
ColmapModel read_colmap_model(const fs::path& dir) {
  ColmapModel m;
  m.cameras = read_colmap_cameras(dir);
  m.images = read_colmap_images(dir);
  m.points = read_colmap_points3D(dir);
  return m;
}
bool has_colmap_points3D(const fs::path& dir) {
  std::error_code ec;
  return fs::is_regular_file(dir / "points3D.bin", ec) || fs::is_regular_file(dir / "points3D.txt", ec);
}

// ---------------------------------------------------------------- writers

std::string colmap_cameras_bin(const std::vector<ColmapCamera>& cameras) {
  std::string out;
  put<std::uint64_t>(out, cameras.size());
  for (const auto& c : cameras) {
    put<std::uint32_t>(out, c.id);
    put<std::int32_t>(out, c.model_id);
    put<std::uint64_t>(out, c.width);
    put<std::uint64_t>(out, c.height);
    for (double p : c.params) put(out, p);
  }
  return out;
}

std::string colmap_images_bin(const std::vector<ColmapImage>& images) {
  std::string out;
  put<std::uint64_t>(out, images.size());
  for (const auto& im : images) {
    put<std::uint32_t>(out, im.id);
    for (double q : im.qvec) put(out, q);
    for (double t : im.tvec) put(out, t);
    put<std::uint32_t>(out, im.camera_id);
    out += im.name;
    out.push_back('\0');
    put<std::uint64_t>(out, im.xys.size());
    for (std::size_t k = 0; k < im.xys.size(); ++k) {
      put(out, im.xys[k][0]);
      put(out, im.xys[k][1]);
      put<std::int64_t>(out, k < im.point3D_ids.size() ? im.point3D_ids[k] : -1);
    }
  }
  return out;
}

std::string colmap_points3D_bin(const std::vector<ColmapPoint3D>& points) {
  std::string out;
  put<std::uint64_t>(out, points.size());
  for (const auto& p : points) {
    put<std::uint64_t>(out, p.id);
    for (double x : p.xyz) put(out, x);
    for (auto c : p.rgb) put(out, c);
    put(out, p.error);
    put<std::uint64_t>(out, p.track.size());
    for (const auto& e : p.track) {
      put(out, e.image_id);
      put(out, e.point2D_idx);
    }
  }
  return out;
}

std::string colmap_cameras_txt(const std::vector<ColmapCamera>& cameras) {
  std::string out =
      "# Camera list with one line of data per camera:\n"
      "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n";
  out += fmt::format("# Number of cameras: {}\n", cameras.size());
  for (const auto& c : cameras) {
    out += fmt::format("{} {} {} {}", c.id, colmap_model_name(c.model_id), c.width, c.height);
    for (double p : c.params) out += fmt::format(" {}", p);
    out += '\n';
  }
  return out;
}

std::string colmap_images_txt(const std::vector<ColmapImage>& images) {
  std::size_t observations = 0;
  for (const auto& im : images) observations += im.xys.size();
  std::string out =
      "# Image list with two lines of data per image:\n"
      "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
      "#   POINTS2D[] as (X, Y, POINT3D_ID)\n";
  out += fmt::format("# Number of images: {}, mean observations per image: {}\n", images.size(),
                     images.empty() ? 0.0 : static_cast<double>(observations) / static_cast<double>(images.size()));
  for (const auto& im : images) {
    out += fmt::format("{} {} {} {} {} {} {} {} {} {}\n", im.id, im.qvec[0], im.qvec[1], im.qvec[2], im.qvec[3],
                       im.tvec[0], im.tvec[1], im.tvec[2], im.camera_id, im.name);
    for (std::size_t k = 0; k < im.xys.size(); ++k) {
      if (k) out += ' ';
      out += fmt::format("{} {} {}", im.xys[k][0], im.xys[k][1], k < im.point3D_ids.size() ? im.point3D_ids[k] : -1);
    }
    out += '\n';
  }
  return out;
}

std::string colmap_points3D_txt(const std::vector<ColmapPoint3D>& points) {
  double track_sum = 0;
  for (const auto& p : points) track_sum += static_cast<double>(p.track.size());
  std::string out =
      "# 3D point list with one line of data per point:\n"
      "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n";
  out += fmt::format("# Number of points: {}, mean track length: {}\n", points.size(),
                     points.empty() ? 0.0 : track_sum / static_cast<double>(points.size()));
  for (const auto& p : points) {
    out += fmt::format("{} {} {} {} {} {} {} {}", p.id, p.xyz[0], p.xyz[1], p.xyz[2], p.rgb[0], p.rgb[1], p.rgb[2],
                       p.error);
    for (const auto& e : p.track) out += fmt::format(" {} {}", e.image_id, e.point2D_idx);
    out += '\n';
  }
  return out;
}

void write_colmap_binary(const ColmapModel& model, const fs::path& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) fail_file(dir, "cannot create folder ({})", ec.message());
  write_file_atomic(dir / "cameras.bin", colmap_cameras_bin(model.cameras));
  write_file_atomic(dir / "images.bin", colmap_images_bin(model.images));
  write_file_atomic(dir / "points3D.bin", colmap_points3D_bin(model.points));
}

void write_colmap_text(const ColmapModel& model, const fs::path& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) fail_file(dir, "cannot create folder ({})", ec.message());
  write_file_atomic(dir / "cameras.txt", colmap_cameras_txt(model.cameras));
  write_file_atomic(dir / "images.txt", colmap_images_txt(model.images));
  write_file_atomic(dir / "points3D.txt", colmap_points3D_txt(model.points));
}

// ---------------------------------------------------------------- conversions

PointCloud colmap_point_cloud(const std::vector<ColmapPoint3D>& points, const fs::path& source) {
  PointCloud cloud;
  cloud.positions.reserve(points.size());
  cloud.colors.reserve(points.size());
  for (const auto& p : points) {
    if (!std::isfinite(p.xyz[0]) || !std::isfinite(p.xyz[1]) || !std::isfinite(p.xyz[2]))
      fail_file(source, "point {} has a non-finite position", p.id);
    // Stored as float: a position beyond its range would become inf there (and the kNN of the initial
    // Gaussians' scales then fails without naming the file).
    for (const double v : p.xyz)
      if (std::abs(v) > 1e30) fail_file(source, "point {} lies at {}, beyond any scene", p.id, v);
    cloud.positions.emplace_back(static_cast<float>(p.xyz[0]), static_cast<float>(p.xyz[1]),
                                 static_cast<float>(p.xyz[2]));
    cloud.colors.emplace_back(p.rgb[0], p.rgb[1], p.rgb[2]);
  }
  return cloud;
}

glm::dmat3 colmap_quaternion_to_matrix(const std::array<double, 4>& qvec, const fs::path& source) {
  const double norm = std::sqrt(qvec[0] * qvec[0] + qvec[1] * qvec[1] + qvec[2] * qvec[2] + qvec[3] * qvec[3]);
  if (!std::isfinite(norm) || norm < 1e-12)
    fail_file(source, "invalid rotation quaternion ({}, {}, {}, {})", qvec[0], qvec[1], qvec[2], qvec[3]);
  const double w = qvec[0] / norm, x = qvec[1] / norm, y = qvec[2] / norm, z = qvec[3] / norm;
  // Row-major entries of the rotation (as COLMAP's QuaternionToRotationMatrix), stored column-major.
  const double r[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)},
                          {2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)},
                          {2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)}};
  glm::dmat3 m;
  for (int row = 0; row < 3; ++row)
    for (int col = 0; col < 3; ++col) m[col][row] = r[row][col];
  return m;
}

// ---------------------------------------------------------------- scene loader

Scene load_colmap_scene(const fs::path& root, const SceneLoadOptions& options) {
  const fs::path sparse = root / "sparse" / "0";
  const auto cameras_path = pick(sparse, "cameras");
  const auto images_path = pick(sparse, "images");
  const auto cameras = read_colmap_cameras(sparse);
  auto images = read_colmap_images(sparse);
  if (images.empty()) fail_file(images_path, "the model has no images");

  Scene scene = empty_scene(root, SceneFormat::Colmap, options);

  std::unordered_map<std::uint32_t, const ColmapCamera*> by_id;
  bool warned_radial = false;
  for (const auto& c : cameras) {
    if (!by_id.emplace(c.id, &c).second) fail_file(cameras_path, "camera id {} appears twice", c.id);
    const auto model = static_cast<ColmapCameraModel>(c.model_id);
    if (model != ColmapCameraModel::Pinhole && model != ColmapCameraModel::SimplePinhole &&
        model != ColmapCameraModel::SimpleRadial)
      fail_file(cameras_path,
                "camera {}: camera model {} is not supported (supported: PINHOLE, SIMPLE_PINHOLE, SIMPLE_RADIAL; "
                "undistort the images first, e.g. with colmap image_undistorter)",
                c.id, colmap_model_name(c.model_id));
    if (c.width == 0 || c.height == 0 || c.width > (1u << 20) || c.height > (1u << 20))
      fail_file(cameras_path, "camera {} has an invalid size {}x{}", c.id, c.width, c.height);
    for (double p : c.params)
      if (!std::isfinite(p)) fail_file(cameras_path, "camera {} has a non-finite parameter", c.id);
    if (c.params[0] <= 0 || (model == ColmapCameraModel::Pinhole && c.params[1] <= 0))
      fail_file(cameras_path, "camera {} has a non-positive focal length", c.id);
    if (model == ColmapCameraModel::SimpleRadial && c.params[3] != 0.0 && !warned_radial) {
      warned_radial = true;
      const auto msg = fmt::format("{}: camera {} is SIMPLE_RADIAL with k = {}; the distortion is ignored",
                                   cameras_path.string(), c.id, c.params[3]);
      spdlog::warn("{}", msg);
      scene.warnings.push_back(msg);
    }
  }

  std::sort(images.begin(), images.end(), [](const ColmapImage& a, const ColmapImage& b) { return a.name < b.name; });
  for (std::size_t i = 1; i < images.size(); ++i)
    if (images[i].name == images[i - 1].name)
      fail_file(images_path, "image name {} appears twice", printable(images[i].name, kNameBytes));
  // points3D's tracks name images by id: two images of one id would make every track through it ambiguous.
  {
    std::unordered_map<std::uint32_t, const std::string*> names_by_id;
    for (const auto& im : images)
      if (const auto [it, fresh] = names_by_id.emplace(im.id, &im.name); !fresh)
        fail_file(images_path, "image id {} appears twice ({} and {})", im.id, printable(*it->second, kNameBytes),
                  printable(im.name, kNameBytes));
  }

  const auto folder = choose_image_folder(root, options.resolution, options.image_source);
  scene.images_folder = folder.folder;
  scene.cameras.reserve(images.size());
  for (const auto& im : images) {
    const auto it = by_id.find(im.camera_id);
    if (it == by_id.end())
      fail_file(images_path, "image {} refers to camera {}, which {} does not define", printable(im.name, kNameBytes),
                im.camera_id, cameras_path.filename().string());
    const ColmapCamera& c = *it->second;
    Camera cam;
    cam.image_name = im.name;
    cam.image_path = root / folder.folder / im.name;
    {
      std::error_code ec;
      if (fs::exists(cam.image_path, ec)) require_regular_file(cam.image_path);  // a pipe or folder: said so
      if (!fs::is_regular_file(cam.image_path, ec))
        fail("{}: image listed in {} not found", printable(cam.image_path.string(), 4096), images_path.string());
    }
    set_camera_image(cam, folder.resample);
    const double sx = static_cast<double>(cam.width) / static_cast<double>(c.width);
    const double sy = static_cast<double>(cam.height) / static_cast<double>(c.height);
    double fx = 0, fy = 0, cx = 0, cy = 0;
    if (static_cast<ColmapCameraModel>(c.model_id) == ColmapCameraModel::Pinhole) {
      fx = c.params[0], fy = c.params[1], cx = c.params[2], cy = c.params[3];
    } else {  // SIMPLE_PINHOLE, SIMPLE_RADIAL: f cx cy [k]
      fx = fy = c.params[0], cx = c.params[1], cy = c.params[2];
    }
    // The intrinsics follow a uniformly resized image; a different aspect ratio is another image.
    if (std::abs(sx / sy - 1.0) > 0.02)
      fail_file(cam.image_path, "image is {}x{} but camera {} in {} is {}x{}: the aspect ratios differ (wrong image?)",
                cam.width, cam.height, c.id, cameras_path.filename().string(), c.width, c.height);
    cam.fx = fx * sx;
    cam.fy = fy * sy;
    cam.cx = cx * sx;
    cam.cy = cy * sy;
    for (double t : im.tvec)
      if (!std::isfinite(t)) fail_file(images_path, "image {} has a non-finite translation", printable(im.name, kNameBytes));
    try {
      cam.R_world_to_cam = colmap_quaternion_to_matrix(im.qvec, images_path);
    } catch (const Error&) {  // the same message, with the image named
      fail_file(images_path, "image {}: invalid rotation quaternion ({}, {}, {}, {})", printable(im.name, kNameBytes),
                im.qvec[0], im.qvec[1], im.qvec[2], im.qvec[3]);
    }
    cam.t_world_to_cam = glm::dvec3(im.tvec[0], im.tvec[1], im.tvec[2]);
    if (const std::string why = implausible_camera(cam); !why.empty())
      fail_file(images_path, "image {} (camera {} of {}): {}", printable(im.name, kNameBytes), c.id,
                cameras_path.filename().string(), why);
    scene.cameras.push_back(std::move(cam));
  }

  if (has_colmap_points3D(sparse)) {
    const auto points_path = pick(sparse, "points3D");
    scene.sfm_points = colmap_point_cloud(read_colmap_points3D(sparse), points_path);
  }
  return scene;
}

}  // namespace d2gs
