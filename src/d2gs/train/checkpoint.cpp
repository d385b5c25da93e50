#include "d2gs/train/checkpoint.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <regex>
#include <stdexcept>
#include <set>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/checksum.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/train/options.hpp"

namespace d2gs {
namespace fs = std::filesystem;
using nlohmann::json;

static_assert(std::endian::native == std::endian::little, "checkpoint arrays are stored little-endian, as in memory");

namespace {

constexpr std::string_view kMagicPrefix = "D2GSCKPT";  // then the format number and '\n'
constexpr std::size_t kCrcBytes = 4;

// Header integers: of JSON integer type and in range (a float or an out-of-range value is damage, never
// converted).
template <typename T>
T integer(const json& j) {
  if (!j.is_number_integer()) throw std::invalid_argument("expected an integer, found " + j.dump());
  if (j.is_number_unsigned()) {
    const auto v = j.get<std::uint64_t>();
    if (v > static_cast<std::uint64_t>(std::numeric_limits<T>::max())) throw std::invalid_argument("out of range: " + j.dump());
    return static_cast<T>(v);
  }
  const auto v = j.get<std::int64_t>();
  if (v < static_cast<std::int64_t>(std::numeric_limits<T>::min()) ||
      (v > 0 && static_cast<std::uint64_t>(v) > static_cast<std::uint64_t>(std::numeric_limits<T>::max())))
    throw std::invalid_argument("out of range: " + j.dump());
  return static_cast<T>(v);
}

template <typename T>
std::vector<T> integers(const json& j) {
  if (!j.is_array()) throw std::invalid_argument("expected an array, found " + j.dump());
  std::vector<T> out;
  out.reserve(j.size());
  for (const auto& v : j) out.push_back(integer<T>(v));
  return out;
}

// ---- the identity of a run ----

json run_to_json(const RunIdentity& r) {
  json sizes = json::array();
  for (const auto& [width, height] : r.train_sizes) sizes.push_back(json::array({width, height}));
  json j = json::object();
  j["scene"] = r.scene;
  j["scene_format"] = r.scene_format;
  j["images_folder"] = r.images_folder;
  j["resolution"] = r.resolution;
  j["scene_images"] = r.scene_images;
  j["split"] = {{"train", r.train_views}, {"test", r.test_views}};
  j["train_images"] = r.train_images;
  j["train_sizes"] = std::move(sizes);
  j["train_image_crcs"] = r.train_image_crcs;
  json cameras = json::array();
  for (const auto& camera : r.train_cameras) {
    json values = json::array();
    for (const double v : camera) values.push_back(v);
    cameras.push_back(std::move(values));
  }
  j["train_cameras"] = std::move(cameras);
  j["options"] = r.options;
  return j;
}

RunIdentity run_from_json(const json& j) {
  RunIdentity r;
  r.scene = j.at("scene").get<std::string>();
  r.scene_format = j.at("scene_format").get<std::string>();
  r.images_folder = j.at("images_folder").get<std::string>();
  r.resolution = integer<int>(j.at("resolution"));
  r.scene_images = integer<int>(j.at("scene_images"));
  r.train_views = integers<int>(j.at("split").at("train"));
  r.test_views = integers<int>(j.at("split").at("test"));
  r.train_images = j.at("train_images").get<std::vector<std::string>>();
  for (const auto& size : j.at("train_sizes")) {
    const auto wh = integers<int>(size);
    if (wh.size() != 2 || wh[0] < 0 || wh[1] < 0) throw std::invalid_argument("an image size is not a width and a height");
    r.train_sizes.push_back({wh[0], wh[1]});
  }
  if (j.contains("train_image_crcs")) {
    r.train_image_crcs = integers<std::uint32_t>(j["train_image_crcs"]);
    if (!r.train_image_crcs.empty() && r.train_image_crcs.size() != r.train_views.size())  // empty: not recorded
      throw std::invalid_argument("the training views and their images' checksums differ in number");
  }
  if (j.contains("train_cameras")) {
    for (const auto& camera : j["train_cameras"]) {
      if (!camera.is_array() || camera.size() != 16) throw std::invalid_argument("a training camera is not 16 numbers");
      std::array<double, 16> values{};
      for (std::size_t k = 0; k < 16; ++k) {
        if (!camera[k].is_number()) throw std::invalid_argument("a training camera holds a value that is not a number");
        values[k] = camera[k].get<double>();
      }
      r.train_cameras.push_back(values);
    }
    if (!r.train_cameras.empty() && r.train_cameras.size() != r.train_views.size())  // empty: not recorded
      throw std::invalid_argument("the training views and their cameras differ in number");
  }
  r.options = j.at("options");
  if (!r.options.is_object()) throw std::invalid_argument("options is not an object");
  if (r.train_images.size() != r.train_views.size() || r.train_sizes.size() != r.train_views.size())
    throw std::invalid_argument("the training views, their names and their sizes differ in number");
  return r;
}

// ---- random streams ----

json rng_to_json(const Rng::State& st) {
  std::uint64_t spare_bits = 0;
  std::memcpy(&spare_bits, &st.spare, sizeof spare_bits);
  return {{"words", {st.words[0], st.words[1], st.words[2], st.words[3]}}, {"spare", spare_bits}, {"has_spare", st.has_spare}};
}

Rng::State rng_from_json(const json& j) {
  Rng::State st{};
  const auto& words = j.at("words");
  if (!words.is_array() || words.size() != 4) throw std::invalid_argument("a random stream needs 4 words");
  for (std::size_t i = 0; i < 4; ++i) st.words[i] = integer<std::uint64_t>(words.at(i));
  const auto spare_bits = integer<std::uint64_t>(j.at("spare"));
  std::memcpy(&st.spare, &spare_bits, sizeof st.spare);
  st.has_spare = j.at("has_spare").get<bool>();
  return st;
}

// ---- body: arrays, each a u64 element count and the elements (little-endian) ----

template <typename T>
std::uint64_t array_bytes(const std::vector<T>& v) {
  return sizeof(std::uint64_t) + v.size() * sizeof(T);
}

template <typename T>
void put_array(std::string& out, const std::vector<T>& v) {
  const std::uint64_t n = v.size();
  out.append(reinterpret_cast<const char*>(&n), sizeof n);
  out.append(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(T));
}

// The attributes of a model, in file order.
template <typename G>
auto attributes(G& g) {
  return std::array{&g.means, &g.log_scales, &g.quats, &g.opacity_logits, &g.sh_dc, &g.sh_rest};
}
constexpr const char* kAttributeNames[] = {"means", "log_scales", "quats", "opacity_logits", "sh_dc", "sh_rest"};

struct BodyReader {
  std::string_view bytes;  // the body alone
  std::size_t pos = 0;
  const fs::path& source;

  template <typename T>
  std::vector<T> array(const std::string& name) {
    std::uint64_t n = 0;
    if (bytes.size() - pos < sizeof n) fail_file(source, "damaged checkpoint: the body ends before array {}", name);
    std::memcpy(&n, bytes.data() + pos, sizeof n);
    pos += sizeof n;
    if (n > (bytes.size() - pos) / sizeof(T))
      fail_file(source, "damaged checkpoint: array {} claims {} values, more than the body holds", name, n);
    std::vector<T> v(static_cast<std::size_t>(n));
    if (n > 0) std::memcpy(v.data(), bytes.data() + pos, static_cast<std::size_t>(n) * sizeof(T));
    pos += static_cast<std::size_t>(n) * sizeof(T);
    return v;
  }

  Gaussians model(const std::string& name, int degree, std::size_t gaussians) {
    Gaussians g;
    g.sh_degree = degree;
    const auto a = attributes(g);
    for (std::size_t k = 0; k < a.size(); ++k) *a[k] = array<float>(name + "." + kAttributeNames[k]);
    try {
      g.validate();
    } catch (const Error& e) {
      fail_file(source, "damaged checkpoint: {}: {}", name, e.what());
    }
    if (g.size() != gaussians)
      fail_file(source, "damaged checkpoint: {} has {} Gaussians, the header says {}", name, g.size(), gaussians);
    return g;
  }
};

std::string join(const std::vector<int>& v) { return fmt::format("[{}]", fmt::join(v, ", ")); }

}  // namespace

RunIdentity run_identity(const Scene& scene, const Split& split, const TrainConfig& config) {
  RunIdentity r;
  r.scene = absolute_path(scene.root.string());
  r.scene_format = to_string(scene.format);
  r.images_folder = scene.images_folder;
  r.resolution = scene.resolution;
  r.scene_images = static_cast<int>(scene.cameras.size());
  r.train_views = split.train;
  r.test_views = split.test;
  for (int v : split.train) {
    const Camera& c = scene.cameras.at(static_cast<std::size_t>(v));
    r.train_images.push_back(c.image_name);
    r.train_sizes.push_back({c.width, c.height});
    r.train_image_crcs.push_back(crc32(read_file(c.image_path)));
    std::array<double, 16> camera{c.fx, c.fy, c.cx, c.cy};
    for (int row = 0; row < 3; ++row) {
      for (int col = 0; col < 3; ++col) camera[static_cast<std::size_t>(4 + row * 3 + col)] = c.R_world_to_cam[col][row];
      camera[static_cast<std::size_t>(13 + row)] = c.t_world_to_cam[row];
    }
    r.train_cameras.push_back(camera);
  }
  r.options = identity_options(config);  // the options that change the training, paths made absolute
  return r;
}

nlohmann::json identity_options(const TrainConfig& config, bool also_scene_and_length) {
  nlohmann::json options = nlohmann::json::object();
  for (const TrainOption& o : train_options()) {
    if (o.role == OptionRole::Output) continue;
    if (o.role != OptionRole::Training && !also_scene_and_length) continue;
    nlohmann::json value = o.get(config);
    // An empty path (no file) stays empty: fs::absolute refuses it.
    if (o.kind == OptionKind::Path && value.is_string() && !value.get<std::string>().empty() &&
        std::find(o.keywords.begin(), o.keywords.end(), value.get<std::string>()) == o.keywords.end())
      value = absolute_path(value.get<std::string>());
    options[o.name] = std::move(value);
  }
  return options;
}

std::string encode_checkpoint(const RunIdentity& run, const TrainingState& s) {
  std::uint64_t body_bytes = 0;
  for (const Gaussians* g : {&s.model, &s.exp_avg, &s.exp_avg_sq})
    for (const auto* a : attributes(*g)) body_bytes += array_bytes(*a);
  for (const auto* a : {&s.grad_sums, &s.grad_counts}) body_bytes += array_bytes(*a);
  // The method's state: its float groups, then its byte groups, each by name.
  json groups = json::array();
  for (const auto& [name, arrays] : s.method.floats) {
    groups.push_back({{"name", name}, {"type", "f32"}, {"arrays", arrays.size()}});
    for (const auto& a : arrays) body_bytes += array_bytes(a);
  }
  for (const auto& [name, arrays] : s.method.bytes) {
    groups.push_back({{"name", name}, {"type", "u8"}, {"arrays", arrays.size()}});
    for (const auto& a : arrays) body_bytes += array_bytes(a);
  }

  const json header = {
      {"format", kCheckpointFormat},
      {"body_bytes", body_bytes},
      {"run", run_to_json(run)},
      {"state",
       {{"iteration", s.iteration},
        {"iterations", s.iterations},
        {"active_sh", s.active_sh},
        {"adam_step", s.adam_step},
        {"elapsed_s", s.elapsed_s},
        {"camera_stack", s.camera_stack},
        {"rng_cameras", rng_to_json(s.rng_cameras)},
        {"rng_dropout", rng_to_json(s.rng_dropout)},
        {"rng_densify", rng_to_json(s.rng_densify)},
        {"gaussians", s.model.size()},
        {"sh_degree", s.model.sh_degree},
        {"method_state", std::move(groups)}}}};
  const std::string text = header.dump();
  const std::string magic = fmt::format("{}{}\n", kMagicPrefix, kCheckpointFormat);
  const std::uint64_t header_bytes = text.size();

  std::string out;
  out.reserve(magic.size() + sizeof header_bytes + text.size() + body_bytes + kCrcBytes);
  out += magic;
  out.append(reinterpret_cast<const char*>(&header_bytes), sizeof header_bytes);
  out += text;
  for (const Gaussians* g : {&s.model, &s.exp_avg, &s.exp_avg_sq})
    for (const auto* a : attributes(*g)) put_array(out, *a);
  for (const auto* a : {&s.grad_sums, &s.grad_counts}) put_array(out, *a);
  for (const auto& [name, arrays] : s.method.floats)
    for (const auto& a : arrays) put_array(out, a);
  for (const auto& [name, arrays] : s.method.bytes)
    for (const auto& a : arrays) put_array(out, a);
  const std::uint32_t crc = crc32(out);
  out.append(reinterpret_cast<const char*>(&crc), sizeof crc);
  return out;
}

Checkpoint decode_checkpoint(std::string_view bytes, const fs::path& source) {
  // Magic and format: "D2GSCKPT<number>\n".
  if (bytes.substr(0, kMagicPrefix.size()) != kMagicPrefix) fail_file(source, "not a d2gs checkpoint");
  const std::size_t newline = bytes.find('\n', kMagicPrefix.size());
  const std::string_view number = newline == std::string_view::npos || newline > kMagicPrefix.size() + 6
                                      ? std::string_view{}
                                      : bytes.substr(kMagicPrefix.size(), newline - kMagicPrefix.size());
  if (number.empty() || !std::all_of(number.begin(), number.end(), [](char c) { return c >= '0' && c <= '9'; }))
    fail_file(source, "not a d2gs checkpoint");
  const int format = std::stoi(std::string(number));
  if (format == 1)
    fail_file(source, "checkpoint format 1 (written by d2gs before 2026-11-25) records neither the scene nor the split "
                      "it was trained on, so a resume from it cannot be checked; train the run again");
  if (format != kCheckpointFormat && format != 2)
    fail_file(source, "checkpoint format {} is not one this d2gs reads (formats 2 and {})", format, kCheckpointFormat);

  // Sizes, then the checksum over everything before it.
  std::size_t pos = newline + 1;
  std::uint64_t header_bytes = 0;
  if (bytes.size() - pos < sizeof header_bytes)
    fail_file(source, "truncated checkpoint ({} bytes, it ends inside its header)", bytes.size());
  std::memcpy(&header_bytes, bytes.data() + pos, sizeof header_bytes);
  pos += sizeof header_bytes;
  if (header_bytes > bytes.size() - pos)
    fail_file(source, "truncated checkpoint ({} bytes, it ends inside its header)", bytes.size());
  json h;
  try {
    h = json::parse(bytes.substr(pos, static_cast<std::size_t>(header_bytes)));
  } catch (const json::exception&) {
    fail_file(source, "damaged checkpoint: its header is not valid JSON");
  }
  pos += static_cast<std::size_t>(header_bytes);
  const json* body_field = h.is_object() && h.contains("body_bytes") ? &h["body_bytes"] : nullptr;
  if (!body_field || !body_field->is_number_unsigned())
    fail_file(source, "damaged checkpoint: its header has no body size");
  const std::uint64_t body_bytes = body_field->get<std::uint64_t>();
  const std::uint64_t available = bytes.size() - pos;
  if (body_bytes > available || available - body_bytes < kCrcBytes)
    fail_file(source, "truncated checkpoint ({} bytes of {})", bytes.size(),
              body_bytes > std::uint64_t{1} << 62 ? std::string("more") : std::to_string(pos + body_bytes + kCrcBytes));
  if (available - body_bytes > kCrcBytes)
    fail_file(source, "damaged checkpoint: {} bytes after its end", available - body_bytes - kCrcBytes);
  std::uint32_t stored = 0;
  std::memcpy(&stored, bytes.data() + bytes.size() - kCrcBytes, kCrcBytes);
  const std::uint32_t computed = crc32(bytes.substr(0, bytes.size() - kCrcBytes));
  if (stored != computed)
    fail_file(source, "damaged checkpoint: CRC-32 mismatch (stored {:08x}, computed {:08x})", stored, computed);

  // The header's fields.
  Checkpoint c;
  TrainingState& s = c.state;
  std::size_t gaussians = 0, masks = 0;
  struct Group {
    std::string name;
    bool f32 = true;
    std::size_t arrays = 0;
  };
  std::vector<Group> groups;
  int sh_degree = 0;
  try {
    c.run = run_from_json(h.at("run"));
    const json& st = h.at("state");
    s.iteration = integer<int>(st.at("iteration"));
    s.iterations = integer<int>(st.at("iterations"));
    s.active_sh = integer<int>(st.at("active_sh"));
    s.adam_step = integer<long>(st.at("adam_step"));
    if (!st.at("elapsed_s").is_number()) throw std::invalid_argument("elapsed_s is not a number");
    s.elapsed_s = st.at("elapsed_s").get<double>();
    s.camera_stack = integers<int>(st.at("camera_stack"));
    s.rng_cameras = rng_from_json(st.at("rng_cameras"));
    s.rng_dropout = rng_from_json(st.at("rng_dropout"));
    s.rng_densify = rng_from_json(st.at("rng_densify"));
    gaussians = integer<std::size_t>(st.at("gaussians"));
    sh_degree = integer<int>(st.at("sh_degree"));
    if (format == 2) {
      masks = integer<std::size_t>(st.at("dafe_masks"));
    } else {
      const json& g = st.at("method_state");
      if (!g.is_array()) throw std::invalid_argument("method_state is not a list");
      std::set<std::string> names;
      for (const json& e : g) {
        Group group{e.at("name").get<std::string>(), true, integer<std::size_t>(e.at("arrays"))};
        const std::string type = e.at("type").get<std::string>();
        if (type != "f32" && type != "u8") throw std::invalid_argument("method state type '" + type + "'");
        group.f32 = type == "f32";
        if (!names.insert(group.name).second) throw std::invalid_argument("method state '" + group.name + "' twice");
        groups.push_back(std::move(group));
      }
    }
  } catch (const std::exception& e) {
    fail_file(source, "damaged checkpoint header ({})", e.what());
  }
  // An impossible state: the field that makes it so.
  const auto impossible = [&](const std::string& what) {
    fail_file(source, "damaged checkpoint: impossible state: {} (iteration {}, --iterations {}, SH degree {} of {})",
              what, s.iteration, s.iterations, s.active_sh, sh_degree);
  };
  if (s.iteration < 0) impossible(fmt::format("iteration {} is negative", s.iteration));
  if (s.iterations < 1) impossible(fmt::format("--iterations {} is below 1", s.iterations));
  if (s.adam_step < 0) impossible(fmt::format("adam_step {} is negative", s.adam_step));
  if (sh_degree < 0 || sh_degree > kMaxShDegree)
    impossible(fmt::format("SH degree {} is outside 0..{}", sh_degree, kMaxShDegree));
  if (s.active_sh < 0 || s.active_sh > sh_degree)
    impossible(fmt::format("active SH degree {} is outside 0..{}", s.active_sh, sh_degree));

  // The arrays.
  BodyReader r{bytes.substr(pos, static_cast<std::size_t>(body_bytes)), 0, source};
  s.model = r.model("model", sh_degree, gaussians);
  s.exp_avg = r.model("exp_avg", sh_degree, gaussians);
  s.exp_avg_sq = r.model("exp_avg_sq", sh_degree, gaussians);
  s.grad_sums = r.array<float>("grad_sums");
  s.grad_counts = r.array<float>("grad_counts");
  if (s.grad_sums.size() != gaussians || s.grad_counts.size() != gaussians)
    fail_file(source, "damaged checkpoint: the densification statistics do not have one value per Gaussian");
  if (format == 2) {
    // D²GS's density cache and DAFE masks at their fixed places; as that method's state groups when
    // they hold anything (every format-2 checkpoint has them, empty for the other methods).
    std::vector<float> density_cache = r.array<float>("density_cache");
    if (masks > r.bytes.size()) fail_file(source, "damaged checkpoint: {} DAFE masks claimed", masks);
    std::vector<std::vector<std::uint8_t>> dafe_masks;
    for (std::size_t k = 0; k < masks; ++k) dafe_masks.push_back(r.array<std::uint8_t>(fmt::format("dafe_masks[{}]", k)));
    if (!density_cache.empty()) s.method.floats["density_cache"] = {std::move(density_cache)};
    if (std::any_of(dafe_masks.begin(), dafe_masks.end(), [](const auto& m) { return !m.empty(); }))
      s.method.bytes["dafe_masks"] = std::move(dafe_masks);
  }
  for (const Group& g : groups) {
    if (g.arrays > r.bytes.size()) fail_file(source, "damaged checkpoint: {} arrays claimed for {}", g.arrays, g.name);
    for (std::size_t k = 0; k < g.arrays; ++k) {
      const std::string name = fmt::format("{}[{}]", g.name, k);
      if (g.f32) s.method.floats[g.name].push_back(r.array<float>(name));
      else s.method.bytes[g.name].push_back(r.array<std::uint8_t>(name));
    }
    if (g.arrays == 0) {  // an empty group is kept as one
      if (g.f32) s.method.floats[g.name];
      else s.method.bytes[g.name];
    }
  }
  if (r.pos != r.bytes.size())
    fail_file(source, "damaged checkpoint: {} body bytes left over after the last array", r.bytes.size() - r.pos);
  return c;
}

void write_checkpoint(const fs::path& path, const RunIdentity& run, const TrainingState& state) {
  write_file_atomic(path, encode_checkpoint(run, state));
}

Checkpoint read_checkpoint(const fs::path& path) { return decode_checkpoint(read_file(path), path); }

std::vector<std::pair<int, fs::path>> checkpoints_in(const fs::path& dir) {
  static const std::regex name("chkpnt([0-9]{1,9})\\.bin");
  std::vector<std::pair<int, fs::path>> found;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    std::smatch m;
    const std::string file = e.path().filename().string();
    if (e.is_regular_file(ec) && std::regex_match(file, m, name)) found.emplace_back(std::stoi(m[1].str()), e.path());
  }
  std::sort(found.begin(), found.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
  return found;
}

std::string check_resume(const fs::path& source, const Checkpoint& checkpoint, const RunIdentity& run, int iterations) {
  const RunIdentity& was = checkpoint.run;
  const TrainingState& s = checkpoint.state;
  const auto refuse = [&source]<typename... Args>(fmt::format_string<Args...> why, Args&&... args) {
    fail_file(source, "cannot resume: {}", fmt::format(why, std::forward<Args>(args)...));
  };
  if (was.scene != run.scene) refuse("it was trained on scene {}, this run reads {}", was.scene, run.scene);
  if (was.scene_format != run.scene_format)
    refuse("it was trained on a {} scene, this run reads a {} scene", was.scene_format, run.scene_format);
  if (was.resolution != run.resolution)
    refuse("it was trained at -r {}, this run uses -r {}", was.resolution, run.resolution);
  if (was.images_folder != run.images_folder)
    refuse("it was trained on the images of {}/, this run reads {}/", was.images_folder, run.images_folder);
  if (was.scene_images != run.scene_images)
    refuse("the scene had {} images when it was written, it has {} now", was.scene_images, run.scene_images);
  if (was.train_views != run.train_views)
    refuse("it was trained on views {}, this run's training views are {}", join(was.train_views), join(run.train_views));
  for (std::size_t k = 0; k < was.train_views.size(); ++k) {
    if (was.train_images[k] != run.train_images[k])
      refuse("training view {} was {}, it is {} now", was.train_views[k], was.train_images[k], run.train_images[k]);
    if (was.train_sizes[k] != run.train_sizes[k])
      refuse("training view {} ({}) was {}×{}, it is {}×{} now", was.train_views[k], run.train_images[k],
             was.train_sizes[k][0], was.train_sizes[k][1], run.train_sizes[k][0], run.train_sizes[k][1]);
    if (!was.train_image_crcs.empty() && k < run.train_image_crcs.size() &&
        was.train_image_crcs[k] != run.train_image_crcs[k])
      refuse("training view {} ({}) has another image file than it was trained on (CRC-32 {:08x}, now {:08x})",
             was.train_views[k], run.train_images[k], was.train_image_crcs[k], run.train_image_crcs[k]);
    if (!was.train_cameras.empty() && k < run.train_cameras.size()) {
      const auto& a = was.train_cameras[k];
      const auto& b = run.train_cameras[k];
      const auto differs = [&](std::size_t from, std::size_t to) {
        for (std::size_t i = from; i < to; ++i)
          if (!(std::abs(a[i] - b[i]) <= 1e-9 * std::max({1.0, std::abs(a[i]), std::abs(b[i])}))) return true;
        return false;
      };
      if (differs(0, 4))
        refuse("training view {} ({}) had the intrinsics fx {} fy {} cx {} cy {}, the scene now gives fx {} fy {} cx {} "
               "cy {}", was.train_views[k], run.train_images[k], a[0], a[1], a[2], a[3], b[0], b[1], b[2], b[3]);
      if (differs(4, 16))
        refuse("training view {} ({}) has another camera pose in the scene's files than it was trained with (centre "
               "moved or turned)", was.train_views[k], run.train_images[k]);
    }
  }
  if (was.test_views != run.test_views)
    refuse("its test views were {}, this run's are {}", join(was.test_views), join(run.test_views));
  // The options under their current names (a checkpoint may use former ones): the method, seed and SH
  // degree first, then the others by name.
  const json was_options = with_current_names(was.options), run_options = with_current_names(run.options);
  std::vector<std::string> keys = {"method", "seed", "sh_degree"};
  std::set<std::string> rest;
  for (const auto& [key, value] : was_options.items()) rest.insert(key);
  for (const auto& [key, value] : run_options.items()) rest.insert(key);
  for (const auto& k : keys) rest.erase(k);
  keys.insert(keys.end(), rest.begin(), rest.end());
  for (const auto& key : keys) {
    const bool in_was = was_options.contains(key), in_run = run_options.contains(key);
    if (in_was && in_run && was_options.at(key) == run_options.at(key)) continue;
    if (!in_was && !in_run) continue;
    // An option newer than the checkpoint: what the code did before the option existed (its default when
    // it was added, options.hpp's value_when_absent), so the run may go on at that value and at nothing else.
    if (!in_was && in_run)
      if (const TrainOption* o = find_train_option(key); o && run_options.at(key) == value_when_absent(*o)) continue;
    refuse("it was trained with {} = {}, this run has {}", key, in_was ? was_options.at(key).dump() : "(no such option)",
           in_run ? run_options.at(key).dump() : "(no such option)");
  }
  // How far to train.
  if (iterations < s.iteration)
    refuse("it is at iteration {}, beyond --iterations {}; resume with --iterations {} or more", s.iteration, iterations,
           s.iteration);
  if (iterations == s.iteration && s.iterations != iterations)
    refuse("it is iteration {} of a {}-iteration run, whose model differs from the last one of a {}-iteration run "
           "(the last iteration takes no optimiser step); resume with --iterations above {}",
           s.iteration, s.iterations, iterations, s.iteration);
  // The state against the run (equal identities make these hold for any file d2gs wrote).
  const std::size_t views = run.train_views.size();
  std::vector<bool> queued(views, false);
  for (int v : s.camera_stack) {
    if (v < 0 || static_cast<std::size_t>(v) >= views || queued[static_cast<std::size_t>(v)])
      refuse("its camera queue names training view position {} of {}", v, views);
    queued[static_cast<std::size_t>(v)] = true;
  }
  if (run.options.contains("sh_degree") && run.options.at("sh_degree") != s.model.sh_degree)
    refuse("its model has SH degree {}, this run trains degree {}", s.model.sh_degree, run.options.at("sh_degree").dump());
  if (iterations != s.iterations)
    return fmt::format("{}: resuming a {}-iteration run to {} iterations: the learning-rate and drop-rate schedules "
                       "change from iteration {} on, so the model is not that of an uninterrupted {}-iteration run",
                       source.string(), s.iterations, iterations, s.iteration + 1, iterations);
  return {};
}

}  // namespace d2gs
