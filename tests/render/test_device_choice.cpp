// --device cpu|cuda|auto (render/device_choice.hpp) and `d2gs info`'s backend: `cuda` that cannot be had
// is a one-line error before any work, `auto` takes a GPU wherever one exists and otherwise the CPU, saying why,
// and runs record what they used.
#include <gtest/gtest.h>

#include <cstdlib>
#include <sstream>
#include <string>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/render/cpu/composite_tiles.hpp"
#include "d2gs/render/cuda/device.hpp"
#include "d2gs/render/device_choice.hpp"
#include "test_paths.hpp"

namespace d2gs {
namespace {
namespace fs = std::filesystem;

std::string fern() { return (test::shared_data() / "nerf_llff_data/fern").string(); }

// True where `auto` chooses CUDA, for rendering and for training alike: wherever a device exists.
bool cuda_usable() { return cuda::device_count() > 0; }

TEST(DeviceChoice, CpuIsAlwaysTheCpu) {
  const render::DeviceChoice c = render::choose_device(render::DeviceRequest::Cpu, render::DeviceWork::Train);
  EXPECT_EQ(c.device, render::Device::Cpu);
  EXPECT_TRUE(c.reason.empty());
  EXPECT_NE(c.description.find("CPU ("), std::string::npos) << c.description;
  EXPECT_NE(c.description.find("OpenMP thread"), std::string::npos) << c.description;
}

TEST(DeviceChoice, AutoFallsBackToTheCpuAndSaysWhy) {
  if (cuda_usable()) GTEST_SKIP() << "CUDA is usable here: auto chooses it";
  const render::DeviceChoice c = render::choose_device(render::DeviceRequest::Auto, render::DeviceWork::Train);
  EXPECT_EQ(c.device, render::Device::Cpu);
  ASSERT_FALSE(c.reason.empty());
  EXPECT_EQ(c.reason, cuda::describe_device());  // "no CUDA device: ..." or "this d2gs was built without CUDA"
  const render::DeviceChoice r = render::choose_device(render::DeviceRequest::Auto, render::DeviceWork::Render);
  EXPECT_EQ(r.device, render::Device::Cpu);
  EXPECT_EQ(r.reason, c.reason);
}

TEST(DeviceChoice, CudaThatCannotBeHadIsAOneLineError) {
  if (cuda::device_count() > 0) GTEST_SKIP() << "a GPU is here: --device cuda is accepted";
  std::string message;
  try {
    render::choose_device(render::DeviceRequest::Cuda, render::DeviceWork::Train);
  } catch (const Error& e) {
    message = e.what();
  }
  ASSERT_FALSE(message.empty()) << "--device cuda was accepted without a usable CUDA backend";
  EXPECT_EQ(message.rfind("--device cuda: ", 0), 0u) << message;
  EXPECT_EQ(message.find('\n'), std::string::npos) << message;
  EXPECT_NE(message.find("use --device cpu or auto"), std::string::npos) << message;
}

// Training with --device cuda on a GPU: the whole step there, the rasterizer alone with regularisers (their
// hooks stay on the CPU), said so.
TEST(DeviceChoice, OnAGpuCudaAndAutoTrainThere) {
  if (cuda::device_count() == 0) GTEST_SKIP() << cuda::describe_device();
  const render::DeviceChoice c = render::choose_device(render::DeviceRequest::Cuda, render::DeviceWork::Train);
  EXPECT_EQ(c.device, render::Device::Cuda);
  EXPECT_NE(c.description.find("the whole training step, or with --regularisers the rasterizer"), std::string::npos)
      << c.description;
  // auto takes the same for training, and CUDA for rendering.
  const render::DeviceChoice a = render::choose_device(render::DeviceRequest::Auto, render::DeviceWork::Train);
  EXPECT_EQ(a.device, render::Device::Cuda);
  EXPECT_EQ(a.description, c.description);
  EXPECT_TRUE(a.reason.empty());
  EXPECT_EQ(render::choose_device(render::DeviceRequest::Auto, render::DeviceWork::Render).device,
            render::Device::Cuda);
}

TEST(DeviceChoice, RequestsParseAndPrint) {
  for (const char* w : {"cpu", "cuda", "auto", "emulated"})
    EXPECT_STREQ(render::to_string(render::parse_device_request(w)), w);
  EXPECT_STREQ(render::to_string(render::Device::Emulated), "emulated");
  try {
    render::parse_device_request("gpu");
    ADD_FAILURE() << "'gpu' was taken";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("--device must be cpu, cuda, auto or emulated (got 'gpu')"), std::string::npos) << e.what();
  }
}

// d2gs train/render/eval: cuda fails before anything is read or written; auto trains on the CPU, logs why,
// and config.json / results.json record the request and the backend used.
TEST(DeviceCli, TrainRenderEvalTakeTheFlag) {
  if (cuda::device_count() > 0) GTEST_SKIP() << "a GPU is here: --device cuda is accepted";
  const auto dir = test::scratch_dir();
  const auto refused = test::run_cli(fmt::format("train -s '{}' -m '{}' -r 8 --n-views 3 --init random --iterations 2 --device cuda",
                                                 fern(), (dir / "refused").string()));
  EXPECT_EQ(refused.exit_code, 1) << refused.output;
  EXPECT_NE(refused.output.find("d2gs: error: --device cuda: "), std::string::npos) << refused.output;
  EXPECT_EQ(test::count_occurrences(refused.output, "\n"), 1u) << refused.output;
  EXPECT_FALSE(fs::exists(dir / "refused")) << "work was done before the device was checked";
  const auto bad = test::run_cli(fmt::format("train -s '{}' -m '{}' --device gpu", fern(), (dir / "bad").string()));
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_NE(bad.output.find("--device"), std::string::npos) << bad.output;

  const auto r = test::run_cli(fmt::format("train -s '{}' -m '{}' -r 8 --n-views 3 --init random --random-points 300 "
                                           "--iterations 2 --quiet",
                                           fern(), (dir / "run").string()));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("--device auto: using the CPU ("), std::string::npos) << r.output;
  const auto config = nlohmann::json::parse(read_file(dir / "run/config.json"));
  EXPECT_EQ(config["device"], "auto");
  EXPECT_EQ(config["device_used"], "cpu");
  EXPECT_EQ(nlohmann::json::parse(read_file(dir / "run/results.json"))["device"], "cpu");
  // The tile loops' level is recorded (runs at different levels round differently): the widest this CPU runs,
  // or the one D2GS_CPU_ISA names.
  const char* isa_env = std::getenv("D2GS_CPU_ISA");
  const std::string level = isa_env && *isa_env ? isa_env : render::cpu::available_tile_isas().back();
  EXPECT_EQ(config["cpu_tile_level"], level);
  EXPECT_EQ(nlohmann::json::parse(read_file(dir / "run/results.json"))["cpu_tile_level"], level);
  {  // and D2GS_CPU_ISA's choice is what is recorded (the child process inherits the variable)
    const bool had_env = isa_env != nullptr;  // setenv may invalidate isa_env: keep what it said
    const std::string saved = had_env ? isa_env : "";
    ::setenv("D2GS_CPU_ISA", "baseline", 1);
    const auto base = test::run_cli(fmt::format("-q train -s '{}' -m '{}' -r 8 --n-views 3 --init random --random-points 300 "
                                                "--iterations 2", fern(), (dir / "baseline").string()));
    if (had_env) ::setenv("D2GS_CPU_ISA", saved.c_str(), 1);
    else ::unsetenv("D2GS_CPU_ISA");
    ASSERT_EQ(base.exit_code, 0) << base.output;
    EXPECT_EQ(nlohmann::json::parse(read_file(dir / "baseline/config.json"))["cpu_tile_level"], "baseline");
    EXPECT_EQ(nlohmann::json::parse(read_file(dir / "baseline/results.json"))["cpu_tile_level"], "baseline");
  }
  // A saved config.json is a valid --config (device_used is recorded, not an option).
  const auto again = test::run_cli(fmt::format("-q train --config '{}' -m '{}' --device cpu",
                                               (dir / "run/config.json").string(), (dir / "again").string()));
  EXPECT_EQ(again.exit_code, 0) << again.output;

  const auto eval_cuda = test::run_cli(fmt::format("-q eval -m '{}' --device cuda", (dir / "run").string()));
  EXPECT_EQ(eval_cuda.exit_code, 1) << eval_cuda.output;
  EXPECT_NE(eval_cuda.output.find("--device cuda: "), std::string::npos) << eval_cuda.output;
  const auto eval_cpu = test::run_cli(fmt::format("-q eval -m '{}' --device cpu --json", (dir / "run").string()));
  ASSERT_EQ(eval_cpu.exit_code, 0) << eval_cpu.output;
  EXPECT_EQ(nlohmann::json::parse(eval_cpu.output)["device"], "cpu");

  const auto render_cuda = test::run_cli(fmt::format("-q render -m '{}' -s '{}' -r 8 --n-views 3 -o '{}' --device cuda",
                                                     (dir / "run/point_cloud/iteration_2/point_cloud.ply").string(), fern(),
                                                     (dir / "renders").string()));
  EXPECT_EQ(render_cuda.exit_code, 1) << render_cuda.output;
  EXPECT_NE(render_cuda.output.find("--device cuda: "), std::string::npos) << render_cuda.output;
  EXPECT_FALSE(fs::exists(dir / "renders"));
}

// --device emulated: the CUDA backend's kernels through the emulator, on any machine. A training run's
// losses follow the CPU's (the rasterizers agree to float rounding: EmulatedRasterizer.*), the run records
// the device, and `eval` scores its model with the emulated kernels as the CPU does.
TEST(DeviceCli, EmulatedKernelsTrainAndEvaluateLikeTheCpu) {
  const render::DeviceChoice c = render::choose_device(render::DeviceRequest::Emulated, render::DeviceWork::Train);
  EXPECT_EQ(c.device, render::Device::Emulated);
  EXPECT_NE(c.description.find("emulated on the CPU"), std::string::npos) << c.description;
  const auto dir = test::scratch_dir();
  nlohmann::json logs[2];
  for (int k = 0; k < 2; ++k) {
    const char* device = k == 0 ? "cpu" : "emulated";
    const fs::path run = dir / device;
    const auto r = test::run_cli(fmt::format("-q train -s '{}' -m '{}' -r 8 --n-views 3 --init random --random-points 400 "
                                             "--iterations 3 --log-every 1 --seed 5 --device {}",
                                             fern(), run.string(), device));
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_EQ(nlohmann::json::parse(read_file(run / "config.json"))["device_used"], device);
    EXPECT_EQ(nlohmann::json::parse(read_file(run / "results.json"))["device"], device);
    logs[k] = nlohmann::json::array();
    std::istringstream lines(read_file(run / "train_log.jsonl"));
    for (std::string line; std::getline(lines, line);)
      if (auto j = nlohmann::json::parse(line); j.contains("loss")) logs[k].push_back(j);
  }
  ASSERT_EQ(logs[0].size(), 3u);
  ASSERT_EQ(logs[1].size(), logs[0].size());
  for (std::size_t i = 0; i < logs[0].size(); ++i) {
    const double a = logs[0][i]["loss"], b = logs[1][i]["loss"];
    EXPECT_GT(a, 0.0);
    EXPECT_NEAR(b, a, 1e-5 * a) << "iteration " << i + 1;
  }
  const auto cpu = test::run_cli(fmt::format("-q eval -m '{}' --device cpu --json", (dir / "cpu").string()));
  const auto emulated = test::run_cli(fmt::format("-q eval -m '{}' --device emulated --json", (dir / "cpu").string()));
  ASSERT_EQ(cpu.exit_code, 0) << cpu.output;
  ASSERT_EQ(emulated.exit_code, 0) << emulated.output;
  const auto je = nlohmann::json::parse(emulated.output), jc = nlohmann::json::parse(cpu.output);
  EXPECT_EQ(je["device"], "emulated");
  EXPECT_NEAR(je["mean"]["PSNR"].get<double>(), jc["mean"]["PSNR"].get<double>(), 1e-3);
}

// The device-resident step (train/kernels/device_step.hpp) in a whole run: D²GS through the emulator (DD-Drop
// on the device, its density scores refreshed on the host at iterations 1 and 5) with densification, an
// opacity reset and its saves and tests brought to the host, against the CPU's run
// (losses and sizes per iteration, the final PSNR), and stopped and resumed from a checkpoint bit for bit.
// The gradient threshold selects every Gaussian seen (a threshold near some Gaussian's statistic could fall
// either way between two runs that differ in the last bits).
TEST(DeviceCli, ResidentStepTrainsLikeTheCpuAndResumes) {
  const auto dir = test::scratch_dir();
  const std::string common = fmt::format(
      "-q train -s '{}' -r 8 --n-views 3 --init random --random-points 400 --method d2gs --iterations 7 "
      "--log-every 1 --seed 3 --densify-from 2 --densify-every 2 --densify-grad-threshold 1e-30 "
      "--opacity-reset-at 6 --test-iterations 4 --density-refresh-every 5",
      fern());
  nlohmann::json logs[2];
  for (int k = 0; k < 2; ++k) {
    const char* device = k == 0 ? "cpu" : "emulated";
    const fs::path run = dir / device;
    const auto r = test::run_cli(fmt::format("{} -m '{}' --device {}", common, run.string(), device));
    ASSERT_EQ(r.exit_code, 0) << r.output;
    logs[k] = nlohmann::json::array();
    std::istringstream lines(read_file(run / "train_log.jsonl"));
    for (std::string line; std::getline(lines, line);) logs[k].push_back(nlohmann::json::parse(line));
  }
  ASSERT_EQ(logs[1].size(), logs[0].size());
  int densified = 0, tested = 0;
  for (std::size_t i = 0; i < logs[0].size(); ++i) {
    const auto &c = logs[0][i], &e = logs[1][i];
    if (c.contains("loss")) {
      const double a = c["loss"], b = e["loss"];
      // The rasterizers' backward sums differ in the last bits (EmulatedRasterizer.*); Adam's normalised steps
      // carry that into the parameters, most for gradients near zero.
      EXPECT_NEAR(b, a, 1e-3 * a) << "line " << i;
      EXPECT_EQ(e["gaussians"], c["gaussians"]) << "line " << i;
      EXPECT_NEAR(e["drop_fraction"].get<double>(), c["drop_fraction"].get<double>(), 1e-12) << "line " << i;
    } else if (c["event"] == "densify") {
      ++densified;
      EXPECT_EQ(e["gaussians"], c["gaussians"]) << "line " << i;
    } else if (c["event"] == "test") {
      ++tested;
      EXPECT_NEAR(e["psnr"].get<double>(), c["psnr"].get<double>(), 1e-2) << "line " << i;
    }
  }
  EXPECT_GE(densified, 2);
  EXPECT_EQ(tested, 1);
  const auto rc = nlohmann::json::parse(read_file(dir / "cpu" / "results.json"));
  const auto re = nlohmann::json::parse(read_file(dir / "emulated" / "results.json"));
  EXPECT_EQ(re["device"], "emulated");
  EXPECT_NEAR(re["mean"]["PSNR"].get<double>(), rc["mean"]["PSNR"].get<double>(), 1e-2);

  // Stopped at 5 (a checkpoint: the model from the device) and resumed (uploaded again): the same model.
  const fs::path split = dir / "stopped";
  const auto stop = test::run_cli(fmt::format("{} -m '{}' --device emulated --stop-at 5", common, split.string()));
  ASSERT_EQ(stop.exit_code, 0) << stop.output;
  const auto resume = test::run_cli(fmt::format("{} -m '{}' --device emulated --resume '{}'", common, split.string(),
                                                (split / "chkpnt5.bin").string()));
  ASSERT_EQ(resume.exit_code, 0) << resume.output;
  EXPECT_EQ(read_file(split / "point_cloud/iteration_7/point_cloud.ply"),
            read_file(dir / "emulated" / "point_cloud/iteration_7/point_cloud.ply"));
}

// d2gs info without a scene: the backend --device auto would use, as a table and as JSON.
TEST(DeviceCli, InfoSaysWhichDeviceWouldBeUsed) {
  const auto table = test::run_cli("info");
  ASSERT_EQ(table.exit_code, 0) << table.output;
  EXPECT_NE(table.output.find("(what --device auto uses for training)"), std::string::npos) << table.output;
  EXPECT_NE(table.output.find("(d2gs render and eval with --device auto)"), std::string::npos) << table.output;
  EXPECT_NE(table.output.find("CUDA "), std::string::npos) << table.output;
  const auto j = test::run_cli("info --json");
  ASSERT_EQ(j.exit_code, 0) << j.output;
  const auto backend = nlohmann::json::parse(j.output)["backend"];
  EXPECT_EQ(backend["device"], cuda_usable() ? "cuda" : "cpu");
  EXPECT_EQ(backend["cuda_devices"], cuda::device_count());
  EXPECT_FALSE(backend["cpu_tile_levels"].empty());
  EXPECT_EQ(backend.contains("reason"), !cuda_usable());
  EXPECT_EQ(backend["render_device"], backend["device"]);
}

}  // namespace
}  // namespace d2gs
