#include "d2gs/eval/evaluate.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "d2gs/core/error.hpp"
#include "d2gs/core/image.hpp"
#include "d2gs/core/interrupt.hpp"
#include "d2gs/eval/image_metrics.hpp"
#include "d2gs/render/device_choice.hpp"
#include "d2gs/render/rasterizer.hpp"

namespace d2gs {

void check_replaceable_render_dir(const std::filesystem::path& dir) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::exists(fs::symlink_status(dir, ec))) return;
  if (!fs::is_directory(fs::symlink_status(dir, ec)))
    fail_file(dir, "exists and is not a folder of test renders; refusing to replace it (move it away)");
  // What evaluate_views() writes: renders/ and gt/, each of PNG files. Anything else is someone's.
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    const std::string name = e.path().filename().string();
    if ((name != "renders" && name != "gt") || !e.is_directory(ec) || e.is_symlink(ec))
      fail_file(dir, "holds {}, which d2gs did not write there; refusing to replace the folder (move it away)", name);
    for (const auto& f : fs::directory_iterator(e.path(), ec))
      if (!f.is_regular_file(ec) || f.is_symlink(ec) || f.path().extension() != ".png")
        fail_file(dir, "holds {}/{}, which d2gs did not write there; refusing to replace the folder (move it away)",
                  name, f.path().filename().string());
  }
  if (ec) fail_file(dir, "cannot read the earlier test renders: {}", ec.message());
}

EvalSummary evaluate_views(const Gaussians& model, const Scene& scene, const std::vector<int>& views,
                           const EvalOptions& options) {
  EvalSummary summary;
  auto rasterizer = render::make_rasterizer(options.device);
  if (options.lpips) {
    summary.lpips_net = options.lpips->description();
    summary.lpips_weights = options.lpips->source().string();
    summary.lpips_range = options.lpips_range;
  } else {
    summary.lpips_skipped = options.lpips_skipped;
  }
  render::RenderOptions ro;
  ro.background = scene.background;
  ro.sh_degree = options.sh_degree;
  // The images go to a sibling folder that replaces render_dir only once every view is scored: a failure or
  // an interruption part-way leaves the earlier set whole (with the results.json it belongs to), never a
  // mix of two evaluations. A killed evaluation's folder is cleared first.
  namespace fs = std::filesystem;
  struct Stage {
    fs::path dir;
    bool armed = false;
    ~Stage() {
      std::error_code ec;
      if (armed) fs::remove_all(dir, ec);
    }
  } stage;
  if (!options.render_dir.empty()) {
    check_replaceable_render_dir(options.render_dir);
    stage.dir = options.render_dir.has_filename() ? options.render_dir : options.render_dir.parent_path();
    stage.dir += ".partial";
    std::error_code ec;
    fs::remove_all(stage.dir, ec);
    stage.armed = true;
  }
  for (int v : views) {
    check_interrupted("while scoring the test views");
    const Camera& cam = scene.cameras.at(static_cast<std::size_t>(v));
    const Image gt = load_image(scene, v);
    const auto& out = rasterizer->forward(model, nullptr, render::make_render_camera(cam), ro);
    Image pred(out.width, out.height, 3);
    for (std::size_t i = 0; i < pred.pixels.size(); ++i) pred.pixels[i] = std::clamp(out.rgb[i], 0.0f, 1.0f);
    ViewMetrics m;
    m.index = v;
    m.name = cam.image_name;
    m.psnr = psnr(pred.pixels.data(), gt.pixels.data(), pred.pixels.size());
    m.ssim = ssim_metric(pred.pixels.data(), gt.pixels.data(), pred.width, pred.height, 3);
    if (options.lpips) {
      m.lpips = options.lpips->distance(pred, gt, options.lpips_range, "view " + cam.image_name + ", render vs ground truth").total;
      m.avge = avge(m.psnr, m.ssim, *m.lpips);
    }
    summary.views.push_back(m);
    if (!options.render_dir.empty()) {
      const std::string stem = std::filesystem::path(cam.image_name).stem().string();
      write_image(stage.dir / "renders" / (stem + ".png"), pred);
      write_image(stage.dir / "gt" / (stem + ".png"), gt);
    }
  }
  if (stage.armed && fs::is_directory(stage.dir)) {
    std::error_code ec;
    fs::remove_all(options.render_dir, ec);
    if (ec) fail_file(options.render_dir, "cannot replace the earlier test renders: {}", ec.message());
    fs::rename(stage.dir, options.render_dir, ec);
    if (ec) fail_file(options.render_dir, "cannot move the test renders into place: {}", ec.message());
    stage.armed = false;
  }
  for (const auto& m : summary.views) {
    summary.psnr += m.psnr;
    summary.ssim += m.ssim;
  }
  if (!summary.views.empty()) {
    const auto n = static_cast<double>(summary.views.size());
    summary.psnr /= n;
    summary.ssim /= n;
    if (options.lpips) {
      double l = 0, a = 0;
      for (const auto& m : summary.views) l += *m.lpips, a += *m.avge;
      summary.lpips = l / n;
      summary.avge = a / n;
    }
  }
  return summary;
}

double avge(double psnr, double ssim, double lpips) {
  const double mse = std::pow(10.0, -psnr / 10.0);
  return std::cbrt(mse * std::sqrt(std::max(0.0, 1.0 - ssim)) * lpips);
}

namespace {
nlohmann::json value_or_null(const std::optional<double>& v) { return v ? nlohmann::json(*v) : nlohmann::json(nullptr); }
std::string cell(const std::optional<double>& v) { return v ? fmt::format("{:>8.4f}", *v) : fmt::format("{:>8}", "-"); }
}  // namespace

void to_json(nlohmann::json& j, const EvalSummary& s) {
  j = nlohmann::json::object();
  j["mean"] = {{"PSNR", s.psnr}, {"SSIM", s.ssim}, {"LPIPS", value_or_null(s.lpips)}, {"AVGE", value_or_null(s.avge)}};
  auto& per = j["per_view"] = nlohmann::json::object();
  for (const auto& v : s.views)
    per[v.name] = {{"index", v.index}, {"PSNR", v.psnr}, {"SSIM", v.ssim}, {"LPIPS", value_or_null(v.lpips)},
                   {"AVGE", value_or_null(v.avge)}};
  if (s.lpips_skipped.empty())
    j["lpips"] = {{"status", "computed"},
                  {"net", s.lpips_net},
                  {"weights", s.lpips_weights},
                  {"input_range", to_string(s.lpips_range)},
                  {"input", fmt::format("images fed in {} ({})", range_label(s.lpips_range),
                                        s.lpips_range == LpipsInputRange::unit ? "as the sparse-view papers"
                                                                              : "the official LPIPS convention")}};
  else
    j["lpips"] = {{"status", "skipped"}, {"reason", s.lpips_skipped}};
}

std::string format_table(const EvalSummary& s) {
  std::string out = fmt::format("{:<24} {:>8} {:>8} {:>8} {:>8}\n", "view", "PSNR", "SSIM", "LPIPS", "AVGE");
  for (const auto& v : s.views)
    out += fmt::format("{:<24} {:>8.3f} {:>8.4f} {} {}\n", v.name, v.psnr, v.ssim, cell(v.lpips), cell(v.avge));
  out += fmt::format("{:<24} {:>8.3f} {:>8.4f} {} {}\n", "mean", s.psnr, s.ssim, cell(s.lpips), cell(s.avge));
  if (s.lpips_skipped.empty())
    out += fmt::format("LPIPS: {}, input {} ({}), weights {}\n", s.lpips_net, range_label(s.lpips_range),
                       to_string(s.lpips_range), s.lpips_weights);
  else
    out += fmt::format("LPIPS skipped: {}; AVGE unavailable\n", s.lpips_skipped);
  return out;
}

}  // namespace d2gs
