#include "d2gs/train/outputs.hpp"

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/render/cpu/composite_tiles.hpp"

namespace d2gs {
namespace fs = std::filesystem;

void write_run_config(const fs::path& model_dir, const TrainConfig& cfg, const Scene& scene, const Split& split,
                      float scene_extent, bool init_is_oracle, render::Device device_used) {
  nlohmann::json j;
  to_json(j, cfg);
  j["init_is_oracle"] = init_is_oracle;
  j["scene_extent"] = scene_extent;
  j["split"] = {{"train", split.train}, {"test", split.test}};
  j["images_folder"] = scene.images_folder;
  j["device_used"] = render::to_string(device_used);
  // The CPU's tile loops round by their lane width: the same seed gives the same run only at the same level.
  if (device_used == render::Device::Cpu) j["cpu_tile_level"] = render::cpu::selected_tile_isa();
  write_file_atomic(model_dir / "config.json", j.dump(2));
}

void write_cameras_json(const fs::path& model_dir, const Scene& scene, const Split& split) {
  nlohmann::json cams = nlohmann::json::array();
  std::vector<int> all = split.train;
  all.insert(all.end(), split.test.begin(), split.test.end());
  int id = 0;
  for (int v : all) {
    const Camera& c = scene.cameras[static_cast<std::size_t>(v)];
    const glm::dmat3 R = c.R_cam_to_world();
    const glm::dvec3 pos = c.center_world();
    nlohmann::json rot = nlohmann::json::array();
    for (int r = 0; r < 3; ++r) rot.push_back({R[0][r], R[1][r], R[2][r]});
    cams.push_back({{"id", id++}, {"img_name", fs::path(c.image_name).stem().string()}, {"width", c.width},
                    {"height", c.height}, {"position", {pos.x, pos.y, pos.z}}, {"rotation", rot}, {"fy", c.fy},
                    {"fx", c.fx}, {"global_index", v}});
  }
  write_file_atomic(model_dir / "cameras.json", cams.dump(1));
}

nlohmann::json write_results_json(const fs::path& model_dir, const EvalSummary& summary, const Scene& scene,
                                  const RunResults& run) {
  nlohmann::json j;
  to_json(j, summary);
  j["method"] = run.method;
  j["iteration"] = run.iteration;
  j["gaussians"] = run.gaussians;
  if (run.train_seconds) j["train_seconds"] = *run.train_seconds;
  j["init_is_oracle"] = run.init_is_oracle;
  if (!run.device.empty()) j["device"] = run.device;
  if (run.device == "cpu") j["cpu_tile_level"] = render::cpu::selected_tile_isa();
  j["image_source"] = to_string(scene.image_source);
  j["images_folder"] = scene.images_folder;
  write_file_atomic(model_dir / "results.json", j.dump(2));
  return j;
}

}  // namespace d2gs
