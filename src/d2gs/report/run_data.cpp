#include "d2gs/report/run_data.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <limits>
#include <regex>
#include <set>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/json_value.hpp"
#include "d2gs/model/ply.hpp"

namespace d2gs::report {
namespace fs = std::filesystem;

namespace {

std::string upper(std::string s) {
  for (char& c : s) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return s;
}

Metrics numeric_entries(const nlohmann::json& object) {
  Metrics m;
  if (!object.is_object()) return m;
  for (const auto& [key, value] : object.items())
    if (value.is_number() && key != "index") m[upper(key)] = value.get<double>();
  return m;
}

// Drops the records at or after `iteration` (a resumed run repeats them).
void truncate_from(std::vector<double>& its, std::vector<std::vector<double>*> columns, double iteration) {
  std::size_t keep = its.size();
  while (keep > 0 && its[keep - 1] >= iteration) --keep;
  its.resize(keep);
  for (auto* c : columns) c->resize(keep);
}

// A log record's optional number: NaN where the key is absent or null (a NaN is written as null).
double log_number(const nlohmann::json& record, const char* key, const fs::path& path, int line) {
  if (!record.contains(key) || record[key].is_null()) return std::nan("");
  if (!record[key].is_number())
    fail_file(path, "line {}: '{}' must be a number, got {}", line, key, json_detail::shown(record[key]));
  return record[key].get<double>();
}

}  // namespace

TrainLog read_train_log(const fs::path& path) {
  require_regular_file(path);
  std::ifstream in(path);
  if (!in) fail_file(path, "cannot be read");
  TrainLog log;
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    if (line.empty()) continue;
    nlohmann::json j;
    try {
      j = nlohmann::json::parse(line);
    } catch (const nlohmann::json::exception&) {
      // A run killed while writing leaves a partial last line: ignore that one only.
      if (in.peek() == std::char_traits<char>::eof()) break;
      fail_file(path, "line {} is not JSON", number);
    }
    if (!j.is_object() || !j.contains("iteration") || !j["iteration"].is_number())
      fail_file(path, "line {} is not a log record with an iteration", number);
    const double it = j["iteration"].get<double>();
    if (j.contains("event") && !j["event"].is_string())
      fail_file(path, "line {}: 'event' must be a string, got {}", number, json_detail::shown(j["event"]));
    const std::string event = j.value("event", "");
    if (event == "test") {
      truncate_from(log.test_iteration, {&log.test_psnr, &log.test_ssim}, it);
      log.test_iteration.push_back(it);
      log.test_psnr.push_back(log_number(j, "psnr", path, number));
      log.test_ssim.push_back(log_number(j, "ssim", path, number));
    } else if (event.empty()) {
      truncate_from(log.iteration, {&log.loss, &log.gaussians, &log.elapsed_s}, it);
      log.iteration.push_back(it);
      log.loss.push_back(log_number(j, "loss", path, number));
      log.gaussians.push_back(log_number(j, "gaussians", path, number));
      log.elapsed_s.push_back(log_number(j, "elapsed_s", path, number));
    }
  }
  return log;
}

Metrics mean_metrics(const nlohmann::json& results) {
  if (!results.is_object()) return {};
  Metrics m = numeric_entries(results.value("mean", nlohmann::json::object()));
  for (const char* key : {"lpips", "avge", "LPIPS", "AVGE"})
    if (results.contains(key) && results[key].is_number() && !m.count(upper(key)))
      m[upper(key)] = results[key].get<double>();
  return m;
}

std::map<std::string, Metrics> view_metrics(const nlohmann::json& results) {
  std::map<std::string, Metrics> out;
  if (!results.is_object() || !results.contains("per_view") || !results["per_view"].is_object()) return out;
  for (const auto& [name, value] : results["per_view"].items()) out[name] = numeric_entries(value);
  return out;
}

std::vector<std::string> metric_order(const std::vector<std::string>& present) {
  std::vector<std::string> out;
  for (const char* known : {"PSNR", "SSIM", "LPIPS", "AVGE"})
    if (std::find(present.begin(), present.end(), known) != present.end()) out.emplace_back(known);
  for (const auto& p : present)
    if (std::find(out.begin(), out.end(), p) == out.end()) out.push_back(p);
  return out;
}

bool lower_is_better(const std::string& metric) {
  const std::string m = upper(metric);
  return m == "LPIPS" || m == "AVGE" || m == "IMR";
}

double ReferenceCamera::depth(const float* x) const {
  return (x[0] - position[0]) * forward[0] + (x[1] - position[1]) * forward[1] + (x[2] - position[2]) * forward[2];
}

std::pair<double, double> tertile_limits(const std::vector<float>& xyz, const ReferenceCamera& camera) {
  std::vector<double> d;
  d.reserve(xyz.size() / 3);
  for (std::size_t i = 0; i + 2 < xyz.size(); i += 3) {
    const double z = camera.depth(&xyz[i]);
    if (z > 0) d.push_back(z);
  }
  if (d.empty()) fail("report: no point lies in front of the reference camera {}", camera.name);
  std::sort(d.begin(), d.end());
  const std::size_t n = d.size();
  return {d[std::min(n - 1, static_cast<std::size_t>(0.33 * static_cast<double>(n)))],
          d[std::min(n - 1, static_cast<std::size_t>(0.67 * static_cast<double>(n)))]};
}

LayerCounts count_layers(const Gaussians& model, const ReferenceCamera& camera, std::pair<double, double> limits) {
  LayerCounts c;
  c.near_limit = limits.first;
  c.far_limit = limits.second;
  c.camera = camera.name;
  for (std::size_t i = 0; i < model.size(); ++i) {
    const double z = camera.depth(&model.means[3 * i]);
    if (!(z > 0)) ++c.behind;
    else if (z < limits.first) ++c.near;
    else if (z < limits.second) ++c.middle;
    else ++c.far;
  }
  return c;
}

std::optional<ReferenceCamera> reference_camera(const fs::path& dir, const nlohmann::json& config) {
  const fs::path path = dir / "cameras.json";
  if (!fs::is_regular_file(path)) return std::nullopt;
  const nlohmann::json cams = read_json_file(path);
  if (!cams.is_array() || cams.empty()) fail_file(path, "expected a non-empty array of cameras");
  std::vector<int> test;
  if (config.is_object() && config.contains("split") && config["split"].is_object() && config["split"].contains("test")) {
    try {
      test = json_number_list<int>(config["split"]["test"], "split.test", 0);
    } catch (const Error& e) {
      fail_file(dir / "config.json", "{}", e.what());
    }
  }
  for (std::size_t i = 0; i < cams.size(); ++i)
    if (!cams[i].is_object()) fail_file(path, "camera entry {} is not an object but {}", i, json_detail::shown(cams[i]));
  const nlohmann::json* pick = nullptr;
  if (!test.empty())
    for (const auto& c : cams)
      if (c.contains("global_index") && c["global_index"].is_number_integer() &&
          c["global_index"].get<std::int64_t>() == test.front())
        pick = &c;
  if (!pick) pick = &cams.back();
  try {
    ReferenceCamera r;
    const auto& p = *pick;
    r.name = fmt::format("{} (image {})", p.contains("img_name") && p["img_name"].is_string() ? p["img_name"].get<std::string>() : "?",
                         p.contains("global_index") ? p["global_index"].dump() : "?");
    const auto& pos = (*pick).at("position");
    const auto& rot = (*pick).at("rotation");  // rows of the camera-to-world rotation
    for (int k = 0; k < 3; ++k) {
      r.position[k] = pos.at(static_cast<std::size_t>(k)).get<double>();
      r.forward[k] = rot.at(static_cast<std::size_t>(k)).at(2).get<double>();
    }
    return r;
  } catch (const nlohmann::json::exception& e) {
    fail_file(path, "camera entry without position/rotation ({})", e.what());
  }
}

std::string RunData::method() const {
  if (results.is_object() && results.contains("method") && results["method"].is_string())
    return results["method"].get<std::string>();
  if (config.is_object() && config.contains("method") && config["method"].is_string())
    return config["method"].get<std::string>();
  return "?";
}

RunData load_run(const fs::path& dir, const RunLoadOptions& options) {
  RunData r;
  r.dir = dir;
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) fail_file(dir, "no such run folder");
  if (!fs::is_regular_file(dir / "config.json")) fail_file(dir, "not a run folder (no config.json)");
  r.config = read_json_file(dir / "config.json");
  if (fs::is_regular_file(dir / "results.json")) {
    r.results = read_json_file(dir / "results.json");
    // What d2gs eval writes: an object whose "mean" (and "per_view" entries) are objects of metrics.
    if (!r.results.is_object()) fail_file(dir / "results.json", "is not a JSON object of results");
    for (const char* key : {"mean", "per_view"})
      if (r.results.contains(key) && !r.results[key].is_object())
        fail_file(dir / "results.json", "key '{}' must be an object, got {}", key, json_detail::shown(r.results[key]));
  }
  if (fs::is_regular_file(dir / "train_log.jsonl")) r.log = read_train_log(dir / "train_log.jsonl");

  const std::regex iteration_re("iteration_([0-9]{1,9})");
  if (fs::is_directory(dir / "point_cloud"))
    for (const auto& e : fs::directory_iterator(dir / "point_cloud")) {
      std::smatch m;
      const std::string name = e.path().filename().string();
      if (std::regex_match(name, m, iteration_re) && fs::is_regular_file(e.path() / "point_cloud.ply")) {
        const int it = std::stoi(m[1]);
        if (it > r.iteration) {
          r.iteration = it;
          r.ply = e.path() / "point_cloud.ply";
        }
      }
    }
  // Test renders: those of the final model, else the highest ours_N.
  const std::regex ours_re("ours_([0-9]{1,9})");
  fs::path renders;
  int best = -1;
  if (fs::is_directory(dir / "test"))
    for (const auto& e : fs::directory_iterator(dir / "test")) {
      std::smatch m;
      const std::string name = e.path().filename().string();
      if (!std::regex_match(name, m, ours_re) || !fs::is_directory(e.path() / "renders")) continue;
      const int it = std::stoi(m[1]);
      if (it == r.iteration) {
        best = std::numeric_limits<int>::max();
        renders = e.path();
      } else if (it > best) {
        best = it;
        renders = e.path();
      }
    }
  if (!renders.empty()) {
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(renders / "renders"))
      if (e.is_regular_file() && e.path().extension() == ".png" &&
          atomic_temporary_writer(e.path().filename().string()) == 0)  // not a killed writer's temporary
        files.push_back(e.path());
    std::sort(files.begin(), files.end());
    for (const auto& f : files) {
      TestView v;
      v.name = f.stem().string();
      v.render = f;
      if (fs::is_regular_file(renders / "gt" / f.filename())) v.gt = renders / "gt" / f.filename();
      r.views.push_back(v);
    }
  }

  if (options.layers) {
    if (r.ply.empty()) {
      r.layers_note = "no saved model";
    } else if (const auto cam = reference_camera(dir, r.config); !cam) {
      r.layers_note = "no cameras.json";
    } else {
      const Gaussians model = read_gaussians_ply(r.ply);
      std::vector<float> boundary;
      std::string source;
      if (fs::is_regular_file(dir / "input.ply")) {
        const PointCloud init = read_point_cloud_ply(dir / "input.ply");
        boundary.reserve(init.positions.size() * 3);
        for (const auto& p : init.positions) boundary.insert(boundary.end(), {p.x, p.y, p.z});
        source = "depth tertiles of the initial points (input.ply)";
      }
      bool in_front = false;
      for (std::size_t i = 0; i + 2 < boundary.size() && !in_front; i += 3) in_front = cam->depth(&boundary[i]) > 0;
      if (!in_front) {
        boundary = model.means;
        source = "depth tertiles of the model itself (no usable input.ply)";
      }
      try {
        LayerCounts c = count_layers(model, *cam, tertile_limits(boundary, *cam));
        c.boundary = source;
        r.layers = c;
      } catch (const Error& e) {
        r.layers_note = e.what();
      }
    }
  }
  return r;
}

}  // namespace d2gs::report
