#include "d2gs/eval/evaluate.hpp"

#include <algorithm>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "d2gs/core/image.hpp"
#include "d2gs/eval/image_metrics.hpp"
#include "d2gs/render/rasterizer.hpp"

namespace d2gs {

EvalSummary evaluate_views(const Gaussians& model, const Scene& scene, const std::vector<int>& views,
                           const EvalOptions& options) {
  EvalSummary summary;
  auto rasterizer = render::make_cpu_rasterizer();
  render::RenderOptions ro;
  ro.background = scene.background;
  ro.sh_degree = options.sh_degree;
  for (int v : views) {
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
    summary.views.push_back(m);
    if (!options.render_dir.empty()) {
      const std::string stem = std::filesystem::path(cam.image_name).stem().string();
      write_image(options.render_dir / "renders" / (stem + ".png"), pred);
      write_image(options.render_dir / "gt" / (stem + ".png"), gt);
    }
  }
  for (const auto& m : summary.views) {
    summary.psnr += m.psnr;
    summary.ssim += m.ssim;
  }
  if (!summary.views.empty()) {
    summary.psnr /= static_cast<double>(summary.views.size());
    summary.ssim /= static_cast<double>(summary.views.size());
  }
  return summary;
}

void to_json(nlohmann::json& j, const EvalSummary& s) {
  j = nlohmann::json::object();
  j["mean"] = {{"PSNR", s.psnr}, {"SSIM", s.ssim}};
  auto& per = j["per_view"] = nlohmann::json::object();
  for (const auto& v : s.views) per[v.name] = {{"index", v.index}, {"PSNR", v.psnr}, {"SSIM", v.ssim}};
}

std::string format_table(const EvalSummary& s) {
  std::string out = fmt::format("{:<24} {:>8} {:>8}\n", "view", "PSNR", "SSIM");
  for (const auto& v : s.views) out += fmt::format("{:<24} {:>8.3f} {:>8.4f}\n", v.name, v.psnr, v.ssim);
  out += fmt::format("{:<24} {:>8.3f} {:>8.4f}\n", "mean", s.psnr, s.ssim);
  return out;
}

}  // namespace d2gs
