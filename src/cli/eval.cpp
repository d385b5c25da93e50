// d2gs eval: render the held-out views of a trained run and score them (method.md §6).
#include <cmath>
#include <cstdlib>
#include <map>
#include <optional>
#include <regex>

#include <nlohmann/json.hpp>

#include "cli/commands.hpp"
#include "cli/device_flag.hpp"
#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/file_lock.hpp"
#include "d2gs/core/json_value.hpp"
#include "d2gs/eval/evaluate.hpp"
#include "d2gs/model/ply.hpp"
#include "d2gs/report/run_report.hpp"
#include "d2gs/train/config.hpp"
#include "d2gs/train/outputs.hpp"
#include "d2gs/train/trainer.hpp"

namespace d2gs::cli {
namespace fs = std::filesystem;

namespace {

// The run's cameras.json names each of its views and records its size and pose (train/outputs.cpp): a
// scene whose test views are other images (another scene given with -s, a folder re-processed since) would
// be scored, and its results.json overwritten, as if it were the run's. The sizes are compared unless the
// ground truth is asked from another image source (whose sizes may round differently). A run without
// cameras.json (or one that names no test view) is not checked.
void check_test_views_are_the_runs(const fs::path& cameras_json, const Scene& scene, const std::vector<int>& test,
                                   const fs::path& scene_dir, bool compare_sizes) {
  std::error_code ec;
  if (!fs::is_regular_file(cameras_json, ec)) return;
  struct Recorded {
    std::string name;
    std::optional<std::pair<int, int>> size;
    std::optional<glm::dvec3> position;
  };
  std::map<int, Recorded> recorded;
  try {
    const nlohmann::json cams = read_json_file(cameras_json);
    if (!cams.is_array()) fail("expected a list of cameras");
    for (const auto& c : cams) {
      if (!c.is_object() || !c.contains("global_index") || !c.contains("img_name") || !c["img_name"].is_string()) continue;
      Recorded r{c["img_name"].get<std::string>(), std::nullopt, std::nullopt};
      if (c.contains("width") && c.contains("height"))
        r.size = std::pair{json_number<int>(c["width"], "width"), json_number<int>(c["height"], "height")};
      if (c.contains("position")) {
        const auto p = json_number_list<double>(c["position"], "position");
        if (p.size() != 3) fail("key 'position' must hold 3 numbers, got {}", p.size());
        r.position = glm::dvec3(p[0], p[1], p[2]);
      }
      recorded[json_number<int>(c["global_index"], "global_index")] = std::move(r);
    }
  } catch (const nlohmann::json::exception& e) {
    fail_file(cameras_json, "cannot read the run's cameras ({})", e.what());
  } catch (const Error& e) {
    fail_file(cameras_json, "cannot read the run's cameras: {}", e.what());
  }
  for (int v : test) {
    const auto it = recorded.find(v);
    if (it == recorded.end()) continue;
    const Camera& cam = scene.cameras[static_cast<std::size_t>(v)];
    const std::string now = fs::path(cam.image_name).stem().string();
    if (now != it->second.name)
      fail_file(cameras_json, "test view {} was image {} when the run was trained, it is {} in {}: not the run's scene",
                v, it->second.name, now, scene_dir.string());
    if (compare_sizes && it->second.size && *it->second.size != std::pair{cam.width, cam.height})
      fail_file(cameras_json, "test view {} ({}) was {}x{} when the run was trained, it is {}x{} in {}: not the run's scene "
                "or resolution", v, now, it->second.size->first, it->second.size->second, cam.width, cam.height,
                scene_dir.string());
    if (it->second.position) {
      // The same loader on the same files gives the same double; 1e-6 relative allows for a rewritten file.
      const glm::dvec3 was = *it->second.position, is = cam.center_world();
      for (int k = 0; k < 3; ++k)
        if (!(std::abs(was[k] - is[k]) <= 1e-6 * (1.0 + std::abs(was[k]))))
          fail_file(cameras_json, "test view {} ({}) was at ({:.6g}, {:.6g}, {:.6g}) when the run was trained, it is at "
                    "({:.6g}, {:.6g}, {:.6g}) in {}: not the run's scene", v, now, was.x, was.y, was.z, is.x, is.y,
                    is.z, scene_dir.string());
    }
  }
}

// The highest point_cloud/iteration_N of a run (or the one asked for).
int pick_iteration(const fs::path& run, int wanted) {
  const fs::path dir = run / "point_cloud";
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) fail_file(dir, "no saved models (expected point_cloud/iteration_N/point_cloud.ply)");
  int best = -1;
  const std::regex re("iteration_([0-9]{1,9})");  // longer numbers are no iteration d2gs saves
  for (const auto& e : fs::directory_iterator(dir)) {
    std::smatch m;
    const std::string name = e.path().filename().string();
    if (std::regex_match(name, m, re) && fs::exists(e.path() / "point_cloud.ply")) {
      const int it = std::stoi(m[1]);
      if (wanted > 0 ? it == wanted : it > best) best = it;
    }
  }
  if (best < 0) {
    if (wanted > 0) fail_file(dir, "has no iteration_{}", wanted);
    fail_file(dir, "holds no iteration_N/point_cloud.ply");
  }
  return best;
}

}  // namespace

Run add_eval_command(CLI::App& app) {
  auto* cmd = app.add_subcommand("eval", "Render the test views of a trained run and write MODEL/results.json");
  cmd->footer("Metrics: PSNR, SSIM, LPIPS and AVGE per view and mean (method.md §6). Renders and ground truth go\n"
              "to MODEL/test/ours_N/{renders,gt}/ as the original render.py writes them. LPIPS needs a weights\n"
              "file (docs/formats.md; tools/convert_lpips_weights.py makes one from the torchvision and LPIPS\n"
              "checkpoints); without one LPIPS is skipped and AVGE reported unavailable (null).");
  auto model_dir = std::make_shared<std::string>();
  auto iteration = std::make_shared<int>(-1);
  auto json_only = std::make_shared<bool>(false);
  auto lpips_weights = std::make_shared<std::string>();
  auto lpips_range = std::make_shared<std::string>("unit");
  auto source = std::make_shared<std::string>();
  if (const char* env = std::getenv("D2GS_LPIPS_WEIGHTS")) *lpips_weights = env;
  add_option(*cmd, "-m,--model-path", *model_dir, "Run folder written by d2gs train")->required();
  add_option(*cmd, "--iteration", *iteration, "Model iteration to evaluate (default: the last saved)")
      ->check(at_least(1));
  cmd->add_flag("--json", *json_only, "Print the results as JSON instead of a table");
  add_option(*cmd, "-s,--source", *source,
             "Scene folder (default: the one recorded in MODEL/config.json; a relative recorded path is taken "
             "relative to MODEL, else to the working folder)");
  add_option(*cmd, "--lpips-weights", *lpips_weights,
             "LPIPS weights (.safetensors, VGG16 or AlexNet; default: $D2GS_LPIPS_WEIGHTS)");
  add_option(*cmd, "--lpips-input-range", *lpips_range,
             "Images fed to LPIPS: unit = [0,1] as the sparse-view papers, symmetric = [-1,1] as LPIPS")
      ->capture_default_str();
  auto image_source = std::make_shared<std::string>();
  add_option(*cmd, "--image-source", *image_source,
             "Ground-truth images: as the run was trained (default, from its config.json), or 'folder' / "
             "'largest' to score the same renders against another source (see d2gs train --image-source)")
      ->check(CLI::IsMember({"folder", "largest"}));
  auto device = std::make_shared<std::string>();
  add_device_flag(*cmd, *device);
  return [model_dir, iteration, json_only, lpips_weights, lpips_range, source, image_source, device]() -> int {
    // Options first, so that a bad weights file or device fails before any rendering.
    const render::DeviceChoice backend = resolve_device_flag(*device, render::DeviceWork::Render);
    const LpipsInputRange range = parse_lpips_input_range(*lpips_range, "--lpips-input-range");
    std::optional<Lpips> lpips;
    if (!lpips_weights->empty()) lpips.emplace(Lpips::load(*lpips_weights));
    const fs::path run = *model_dir;
    const fs::path cfg_path = run / "config.json";
    nlohmann::json cj = read_json_file(cfg_path);
    if (!cj.is_object() || !cj.contains("split") || !cj["split"].is_object() || !cj["split"].contains("test"))
      fail_file(cfg_path, "has no recorded split");
    std::vector<int> test;
    TrainConfig c;
    bool oracle = false;
    try {
      test = json_number_list<int>(cj["split"]["test"], "split.test", 0);
      if (test.empty()) fail("records no test views (split.test is empty): nothing to evaluate");
      if (cj.contains("init_is_oracle") && !cj["init_is_oracle"].is_boolean())
        fail("key 'init_is_oracle' must be true or false");
      oracle = cj.value("init_is_oracle", false);
      take_recorded_run_config(c, cj);  // an older run without image_source was trained on images_R/
      check_resolution(c.resolution);     // the scene is loaded at it below
    } catch (const Error& e) {
      fail_file(cfg_path, "{}", e.what());
    }
    if (!image_source->empty()) c.image_source = image_source_from_string(*image_source);
    fs::path scene_dir = *source;
    if (scene_dir.empty()) {
      scene_dir = recorded_source(run, c.source);
      std::error_code ec;
      if (!fs::is_directory(scene_dir, ec))
        fail_file(cfg_path, "records the scene '{}', which is not a folder from here (give the scene with -s)", c.source);
    }
    const Scene scene = load_scene(scene_dir, scene_load_options(c));
    for (int v : test)
      if (v < 0 || static_cast<std::size_t>(v) >= scene.cameras.size()) fail_file(cfg_path, "test view {} is not in the scene", v);
    check_test_views_are_the_runs(run / "cameras.json", scene, test, scene_dir, image_source->empty());
    // One process at a time in a run folder: a training still running there (or another eval) would mix its
    // results.json and test renders with these.
    const std::optional<FileLock> lock = FileLock::try_acquire(run / kRunFolderLock);
    if (!lock)
      fail_file(run, "a d2gs train or eval{} is working in this folder: evaluate it once that has ended",
                lock_holder_note(run / kRunFolderLock));
    const int it = pick_iteration(run, *iteration);
    check_replaceable_render_dir(run / "test" / fmt::format("ours_{}", it));  // before the model is read
    const fs::path ply = run / "point_cloud" / fmt::format("iteration_{}", it) / "point_cloud.ply";
    const Gaussians model = read_gaussians_ply(ply);
    if (model.size() == 0) fail_file(ply, "the model has no Gaussians (0 vertices): nothing to evaluate");
    EvalOptions eo;
    eo.render_dir = run / "test" / fmt::format("ours_{}", it);
    eo.lpips = lpips ? &*lpips : nullptr;
    eo.lpips_range = range;
    eo.lpips_skipped = "no LPIPS weights given (--lpips-weights FILE or D2GS_LPIPS_WEIGHTS)";
    eo.device = backend;
    log_device_choice(backend);
    const EvalSummary summary = evaluate_views(model, scene, test, eo);
    // The training time d2gs train recorded stays with the results of the same iteration (the tables of
    // d2gs experiment show it); results of another iteration have none.
    std::optional<double> train_seconds;
    try {
      const nlohmann::json before = nlohmann::json::parse(read_file(run / "results.json"));
      if (before.value("iteration", -1) == it && before.contains("train_seconds") && before["train_seconds"].is_number())
        train_seconds = before["train_seconds"].get<double>();
    } catch (const std::exception&) {  // none, or not readable: the new results are written without it
    }
    const nlohmann::json j = write_results_json(run, summary, scene,
                                                {.method = c.method, .iteration = it, .gaussians = model.size(),
                                                 .init_is_oracle = oracle, .train_seconds = train_seconds,
                                                 .device = render::to_string(backend.device)});
    if (*json_only) std::printf("%s\n", j.dump(2).c_str());
    else std::printf("%s(%s, iteration %d, %zu Gaussians%s)\nwritten %s\n", format_table(summary).c_str(),
                     c.method.c_str(), it, model.size(), oracle ? ", ORACLE init" : "", (run / "results.json").c_str());
    report::write_run_report_or_warn(run);
    return 0;
  };
}

}  // namespace d2gs::cli
