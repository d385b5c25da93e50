#pragma once
// Rendering and scoring held-out views (method.md §6): render each view at training resolution with
// the final model, no dropout, clamp to [0, 1], score against the ground truth.
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "d2gs/eval/lpips.hpp"
#include "d2gs/model/gaussians.hpp"
#include "d2gs/render/device_choice.hpp"
#include "d2gs/scene/scene.hpp"

namespace d2gs {

struct ViewMetrics {
  int index = 0;  // global image index
  std::string name;
  double psnr = 0, ssim = 0;
  std::optional<double> lpips, avge;  // empty when LPIPS was skipped
};

struct EvalSummary {
  std::vector<ViewMetrics> views;
  double psnr = 0, ssim = 0;          // means over views
  std::optional<double> lpips, avge;  // means over views; empty when LPIPS was skipped
  // How LPIPS was computed ("vgg16 (taps ...)", the weights file, the input range) or why it was skipped.
  std::string lpips_net, lpips_weights, lpips_skipped;
  LpipsInputRange lpips_range = LpipsInputRange::unit;
};

struct EvalOptions {
  int sh_degree = -1;  // -1: the model's
  // The renderer: the CPU reference (default) or the CUDA backend's (render::choose_device).
  render::DeviceChoice device{render::Device::Cpu, "CPU", ""};
  // When set, writes DIR/renders/NAME.png and DIR/gt/NAME.png (the layout of the original render.py).
  std::filesystem::path render_dir;
  // LPIPS network (not owned); when null, LPIPS and AVGE are reported unavailable with `lpips_skipped`.
  const Lpips* lpips = nullptr;
  LpipsInputRange lpips_range = LpipsInputRange::unit;
  std::string lpips_skipped = "no LPIPS weights given (d2gs eval --lpips-weights FILE)";
};

// Writes the renders when options.render_dir is set, replacing an earlier set there whole once every view is
// scored; a render_dir that holds anything else than an earlier set (renders/ and gt/ of PNG files) is refused
// first (check_replaceable_render_dir), so that no file d2gs did not write is removed.
EvalSummary evaluate_views(const Gaussians& model, const Scene& scene, const std::vector<int>& views,
                           const EvalOptions& options = {});
// Throws d2gs::Error naming `dir` when it exists and is not a folder of earlier test renders.
void check_replaceable_render_dir(const std::filesystem::path& dir);
// AVGE of one image (method.md §6): the geometric mean of 10^(−PSNR/10), sqrt(1 − SSIM) and LPIPS.
double avge(double psnr, double ssim, double lpips);
// "mean" and "per_view" with PSNR, SSIM, LPIPS, AVGE (null when unavailable) and "lpips": how it was
// computed ({"status": "computed", "net", "weights", "input_range", "input"}) or {"status": "skipped", "reason"}.
void to_json(nlohmann::json& j, const EvalSummary& s);
// A readable table: one row per view and the mean, then a line saying how LPIPS was computed or why not.
std::string format_table(const EvalSummary& s);

}  // namespace d2gs
