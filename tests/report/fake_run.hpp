#pragma once
// A small, fully known run folder in the layout `d2gs train` writes, built without training: a camera at
// the origin looking down +z, an initial cloud at depths 1..9, a model with known depths, two test views.
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/image.hpp"
#include "d2gs/model/ply.hpp"

namespace d2gs::test {

inline Image gradient_image(int w, int h, float shift) {
  Image im(w, h, 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      im.at(x, y, 0) = static_cast<float>(x) / static_cast<float>(w);
      im.at(x, y, 1) = static_cast<float>(y) / static_cast<float>(h);
      im.at(x, y, 2) = shift;
    }
  return im;
}

// Model depths (z of the means): 0.5, 2 near; 3, 5, 6.9 middle; 7, 10 far; -1 behind. The initial cloud's
// depths 1..9 put the layer limits at 3 and 7.
inline void make_fake_run(const std::filesystem::path& dir, const std::string& method = "d2gs",
                          const nlohmann::json& results_extra = nlohmann::json::object()) {
  namespace fs = std::filesystem;
  fs::create_directories(dir);
  nlohmann::json config = {{"source", "/data/scene"}, {"resolution", 8}, {"method", method}, {"iterations", 30},
                           {"seed", 1}, {"init", "random"}, {"preset", ""}, {"scene_preset", ""},
                           {"init_is_oracle", false}, {"split", {{"train", {1, 2}}, {"test", {0, 3}}}}};
  write_file_atomic(dir / "config.json", config.dump(2));
  nlohmann::json cams = nlohmann::json::array();
  for (int k : {1, 2, 0, 3})
    cams.push_back({{"id", cams.size()}, {"img_name", "image" + std::to_string(k)}, {"width", 32}, {"height", 24},
                    {"position", {k == 0 ? 0.0 : 5.0, 0.0, 0.0}},
                    {"rotation", {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}}, {"fx", 30}, {"fy", 30}, {"global_index", k}});
  write_file_atomic(dir / "cameras.json", cams.dump(1));
  PointCloud init;
  for (int z = 1; z <= 9; ++z) {
    init.positions.push_back({0.0f, 0.0f, static_cast<float>(z)});
    init.colors.push_back({128, 128, 128});
  }
  write_point_cloud_ply(dir / "input.ply", init);
  Gaussians g;
  const std::vector<float> depths = {0.5f, 2.0f, 3.0f, 5.0f, 6.9f, 7.0f, 10.0f, -1.0f};
  g.resize(depths.size(), 0);
  for (std::size_t i = 0; i < depths.size(); ++i) {
    g.means[3 * i + 2] = depths[i];
    g.quats[4 * i] = 1.0f;
  }
  write_gaussians_ply(dir / "point_cloud/iteration_30/point_cloud.ply", g);
  std::string log;
  for (int it = 10; it <= 30; it += 10)
    log += nlohmann::json{{"iteration", it}, {"loss", 0.5 / it}, {"gaussians", 8}, {"elapsed_s", it * 0.1}}.dump() + "\n";
  log += nlohmann::json{{"event", "test"}, {"iteration", 20}, {"psnr", 14.5}, {"ssim", 0.5}}.dump() + "\n";
  write_file_atomic(dir / "train_log.jsonl", log);
  for (const char* view : {"image0", "image3"}) {
    write_image(dir / "test/ours_30/renders" / (std::string(view) + ".png"), gradient_image(32, 24, 0.25f));
    write_image(dir / "test/ours_30/gt" / (std::string(view) + ".png"), gradient_image(32, 24, 0.5f));
  }
  nlohmann::json results = {{"mean", {{"PSNR", 15.25}, {"SSIM", 0.5125}}},
                            {"per_view", {{"image0.png", {{"index", 0}, {"PSNR", 15.0}, {"SSIM", 0.5}}},
                                          {"image3.png", {{"index", 3}, {"PSNR", 15.5}, {"SSIM", 0.525}}}}},
                            {"method", method}, {"iteration", 30}, {"gaussians", 8}, {"train_seconds", 3.0},
                            {"lpips", "skipped: no LPIPS weights"}};
  for (const auto& [k, v] : results_extra.items()) results[k] = v;
  write_file_atomic(dir / "results.json", results.dump(2));
}

// Checks that every non-void element is closed in order (the report's HTML, SVG included). Returns an
// empty string when balanced, else a description of the first problem. Script bodies are skipped.
inline std::string check_balanced(const std::string& html) {
  static const std::vector<std::string> kVoid = {"meta", "img", "br", "hr", "link", "input", "!DOCTYPE"};
  std::vector<std::string> stack;
  std::size_t i = 0;
  while ((i = html.find('<', i)) != std::string::npos) {
    const std::size_t end = html.find('>', i);
    if (end == std::string::npos) return "unterminated tag at " + std::to_string(i);
    std::string tag = html.substr(i + 1, end - i - 1);
    const bool closing = !tag.empty() && tag[0] == '/';
    const bool self_closing = !tag.empty() && tag.back() == '/';
    std::string name = tag.substr(closing ? 1 : 0);
    name = name.substr(0, name.find_first_of(" \t\n/"));
    i = end + 1;
    if (std::find(kVoid.begin(), kVoid.end(), name) != kVoid.end() || self_closing) continue;
    if (closing) {
      if (stack.empty() || stack.back() != name)
        return "</" + name + "> closes <" + (stack.empty() ? std::string("nothing") : stack.back()) + ">";
      stack.pop_back();
    } else {
      stack.push_back(name);
      if (name == "script" || name == "style") {
        const std::size_t close = html.find("</" + name + ">", i);
        if (close == std::string::npos) return "unclosed <" + name + ">";
        i = close;
      }
    }
  }
  return stack.empty() ? std::string() : "unclosed <" + stack.back() + ">";
}

// Decodes standard base64 (test helper; the library only encodes).
inline std::string base64_decode(const std::string& in) {
  auto value = [](char c) -> int {
    if (c >= 'A' && c <= 'Z') return c - 'A';
    if (c >= 'a' && c <= 'z') return c - 'a' + 26;
    if (c >= '0' && c <= '9') return c - '0' + 52;
    if (c == '+') return 62;
    if (c == '/') return 63;
    return -1;
  };
  std::string out;
  unsigned buffer = 0;
  int bits = 0;
  for (char c : in) {
    const int v = value(c);
    if (v < 0) break;
    buffer = (buffer << 6) | static_cast<unsigned>(v);
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out += static_cast<char>((buffer >> bits) & 0xff);
    }
  }
  return out;
}

}  // namespace d2gs::test
