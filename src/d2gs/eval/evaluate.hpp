#pragma once
// Rendering and scoring held-out views (method.md §6): render each view at training resolution with
// the final model, no dropout, clamp to [0, 1], score against the ground truth.
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "d2gs/model/gaussians.hpp"
#include "d2gs/scene/scene.hpp"

namespace d2gs {

struct ViewMetrics {
  int index = 0;  // global image index
  std::string name;
  double psnr = 0, ssim = 0;
};

struct EvalSummary {
  std::vector<ViewMetrics> views;
  double psnr = 0, ssim = 0;  // means over views
};

struct EvalOptions {
  int sh_degree = -1;  // -1: the model's
  // When set, writes DIR/renders/NAME.png and DIR/gt/NAME.png (the layout of the original render.py).
  std::filesystem::path render_dir;
};

EvalSummary evaluate_views(const Gaussians& model, const Scene& scene, const std::vector<int>& views,
                           const EvalOptions& options = {});
void to_json(nlohmann::json& j, const EvalSummary& s);
// A readable table: one row per view and the mean.
std::string format_table(const EvalSummary& s);

}  // namespace d2gs
