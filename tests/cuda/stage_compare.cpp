#include "cuda/stage_compare.hpp"

#include "d2gs/model/ply.hpp"
#include "d2gs/render/rasterizer.hpp"
#include "d2gs/scene/scene.hpp"
#include "d2gs/train/initialize.hpp"
#include "test_paths.hpp"

namespace d2gs::test {

FernCase load_fern_case() {
  const auto fern = shared_data() / "nerf_llff_data/fern";
  SceneLoadOptions load;
  load.resolution = 8;
  const Scene scene = load_scene(fern, load);
  FernCase c;
  const std::size_t n = scene.sfm_points.size();
  std::mt19937 rng(27);
  std::normal_distribution<float> g(0.0f, 1.0f);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  auto& m = c.model;
  m.sh_degree = 3;
  for (std::size_t i = 0; i < n; ++i) {
    for (int k = 0; k < 3; ++k) {
      m.means.push_back(scene.sfm_points.positions[i][k]);
      m.log_scales.push_back(std::log(0.01f) + 0.7f * g(rng));
      m.sh_dc.push_back((scene.sfm_points.colors[i][k] / 255.0f - 0.5f) / 0.28209479f);
    }
    for (int k = 0; k < 4; ++k) m.quats.push_back(g(rng) + (k == 0 ? 1.0f : 0.0f));
    const float op = 0.02f + 0.97f * u(rng);
    m.opacity_logits.push_back(std::log(op / (1 - op)));
    for (int k = 0; k < m.K() * 3; ++k) m.sh_rest.push_back(0.2f * g(rng));
    m.multiplier.push_back(i % 5 == 0 ? 0.0f : 1.0f / 0.8f);
  }
  for (std::size_t v : {std::size_t{1}, std::size_t{9}}) c.cameras.push_back(render::make_render_camera(scene.cameras.at(v)));
  return c;
}

FernCase load_fern_published_case() {
  const auto root = shared_data();
  SceneLoadOptions load;
  load.resolution = 8;
  const Scene scene = load_scene(root / "nerf_llff_data/fern", load);
  const Gaussians g = gaussians_from_point_cloud(read_point_cloud_ply(root / "published_init/fern/3_views_fused.ply"), 3);
  FernCase c;
  auto& m = c.model;
  m.sh_degree = g.sh_degree;
  m.means = g.means;
  m.log_scales = g.log_scales;
  m.quats = g.quats;
  m.sh_dc = g.sh_dc;
  std::mt19937 rng(28);
  std::normal_distribution<float> n(0.0f, 1.0f);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (std::size_t i = 0; i < g.size(); ++i) {
    // Opacities of a model in training, a tenth of them past the 0.99 clamp.
    const float op = i % 10 == 0 ? 0.995f + 0.004f * u(rng) : 0.05f + 0.9f * u(rng);
    m.opacity_logits.push_back(std::log(op / (1 - op)));
    for (int k = 0; k < 3; ++k) m.log_scales[i * 3 + k] += 0.3f * n(rng);
    m.multiplier.push_back(i % 5 == 0 ? 0.0f : 1.0f / 0.8f);
  }
  for (float v : g.sh_rest) m.sh_rest.push_back(v + 0.05f * n(rng));
  for (std::size_t v : {std::size_t{1}, std::size_t{9}}) c.cameras.push_back(render::make_render_camera(scene.cameras.at(v)));
  return c;
}

}  // namespace d2gs::test
