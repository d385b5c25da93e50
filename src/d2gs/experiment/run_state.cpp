#include "d2gs/experiment/run_state.hpp"

#include <fstream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/file_lock.hpp"
#include "d2gs/core/json_value.hpp"
#include "d2gs/report/run_data.hpp"
#include "d2gs/train/checkpoint.hpp"
#include "d2gs/train/config.hpp"
#include "d2gs/train/options.hpp"
#include "d2gs/train/progress.hpp"

namespace d2gs::experiment {
namespace fs = std::filesystem;

namespace {

// The last non-empty line of a log, lines ending at '\n' or at the progress line's '\r'.
std::string last_log_line(const fs::path& log) {
  const std::string text = read_file(log);
  std::size_t end = text.size();
  while (end > 0) {
    const std::size_t begin = text.find_last_of("\r\n", end - 1);
    const std::size_t from = begin == std::string::npos ? 0 : begin + 1;
    if (from < end) return text.substr(from, end - from);
    if (begin == std::string::npos) break;
    end = begin;
  }
  return {};
}

// The last iteration line of train_log.jsonl (lines with "elapsed_s"; events and a line still being
// written are passed over: report::read_train_log would refuse the whole file for that last line).
void read_train_log(const fs::path& path, RunState& s) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) return;  // a named pipe would block the open
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) {
    if (line.find("\"elapsed_s\"") == std::string::npos) continue;
    const auto j = nlohmann::json::parse(line, nullptr, false);
    if (j.is_discarded() || !j.is_object() || !j.contains("iteration") || !j["iteration"].is_number_integer() ||
        !j["elapsed_s"].is_number())
      continue;
    s.iteration = j["iteration"].get<int>();
    s.elapsed_s = j["elapsed_s"].get<double>();
  }
}

// The run's --iterations as its training configuration gives them, 0 when it does not.
int run_iterations(const RunSpec& run) {
  const nlohmann::json& c = run.train_config;
  return c.is_object() && c.contains("iterations") && c["iterations"].is_number_integer() ? c["iterations"].get<int>()
                                                                                          : 0;
}

void read_results(const fs::path& path, RunState& s) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) {
    s.message = "results.json is not a regular file";
    return;
  }
  std::ifstream in(path);
  const auto j = nlohmann::json::parse(in, nullptr, false);  // discarded (not an object) when unreadable
  const report::Metrics mean = report::mean_metrics(j);
  if (!mean.count("PSNR") || !mean.count("SSIM")) {
    s.message = "results.json has no mean PSNR and SSIM";
    return;
  }
  s.psnr = mean.at("PSNR");
  s.ssim = mean.at("SSIM");
  if (j.contains("train_seconds") && j["train_seconds"].is_number()) s.train_seconds = j["train_seconds"].get<double>();
  if (j.contains("gaussians") && j["gaussians"].is_number()) s.gaussians = j["gaussians"].get<long>();
}

}  // namespace

const char* to_string(RunPhase p) {
  switch (p) {
    case RunPhase::Pending: return "pending";
    case RunPhase::Running: return "running";
    case RunPhase::Interrupted: return "interrupted";
    case RunPhase::Failed: return "failed";
    case RunPhase::Finished: return "finished";
  }
  return "?";
}

std::string finished_run_differs(const fs::path& out_dir, const RunSpec& run) {
  // Scores of another iteration than the run's last (d2gs eval --iteration N wrote them) are not its row.
  {
    std::ifstream in(out_dir / run.dir / "results.json");
    const auto j = nlohmann::json::parse(in, nullptr, false);
    const int last = run_iterations(run);
    if (j.is_object() && j.contains("iteration") && j["iteration"].is_number_integer() && last > 0 &&
        j["iteration"].get<int>() != last)
      return fmt::format("its results.json scores iteration {}, not the last of its {} (d2gs eval --iteration wrote "
                         "it; d2gs eval -m {} scores the final model again)",
                         j["iteration"].get<int>(), last, (out_dir / run.dir).string());
  }
  const fs::path recorded_file = out_dir / run.dir / "config.json";
  nlohmann::json was, now;
  try {
    TrainConfig recorded, expected;
    take_recorded_run_config(recorded, read_json_file(recorded_file));
    update_from_json(expected, run.train_config);
    was = identity_options(recorded, true);
    now = identity_options(expected, true);
  } catch (const std::exception& e) {
    return fmt::format("its config.json cannot be compared ({})", e.what());
  }
  // Options held in single precision read back as doubles like 0.05000000074505806: shown as floats.
  const auto show = [](const nlohmann::json& v) {
    return v.is_number_float() ? fmt::format("{:.7g}", v.get<double>()) : v.dump();
  };
  for (const TrainOption& o : train_options()) {
    if (!now.contains(o.name)) continue;
    const nlohmann::json then = was.value(o.name, nlohmann::json());
    if (then != now.at(o.name))
      return fmt::format("{} was {}, the experiment now gives {}", o.name, show(then), show(now.at(o.name)));
  }
  return {};
}

void check_finished_runs_match(const fs::path& out_dir, const std::vector<RunSpec>& runs) {
  for (const RunSpec& run : runs) {
    std::error_code ec;
    if (!fs::is_regular_file(out_dir / run.dir / "results.json", ec)) continue;
    if (const std::string why = finished_run_differs(out_dir, run); !why.empty())
      fail_file(out_dir / run.dir, "run {} finished with another configuration than the experiment now gives it ({}); "
                                   "move the folder away to train it again, or give the changed method another variant",
                run.index, why);
  }
}

RunState inspect_run(const fs::path& out_dir, const RunSpec& run, long ended_holder) {
  RunState s;
  const fs::path dir = out_dir / run.dir;
  const fs::path log = out_dir / "logs" / (run.id() + ".log");
  s.iterations = run_iterations(run);
  std::error_code ec;
  if (fs::is_regular_file(dir / "results.json", ec)) {
    s.phase = RunPhase::Finished;
    read_results(dir / "results.json", s);
    s.differs = finished_run_differs(out_dir, run);
    return s;
  }
  if (!fs::exists(log, ec)) return s;  // pending
  read_train_log(dir / "train_log.jsonl", s);
  if (fs::is_directory(dir, ec)) {
    const auto checkpoints = checkpoints_in(dir);
    if (!checkpoints.empty()) s.checkpoint = checkpoints.front().first;
  }
  const fs::path lock = out_dir / "logs" / (run.id() + ".lock");
  const long holder = lock_file_holder(lock);
  if (holder != ended_holder && lock_holder_running(lock)) {
    s.phase = RunPhase::Running;
    s.pid = holder;
    return s;
  }
  const std::string last = last_log_line(log);
  if (last.rfind("d2gs: error:", 0) == 0) {
    s.phase = RunPhase::Failed;
    s.message = last;
  } else {
    s.phase = RunPhase::Interrupted;
  }
  return s;
}

std::string describe(const RunState& s) {
  const std::string at = s.iteration > 0 ? fmt::format("at iteration {}/{}", s.iteration, s.iterations)
                                          : std::string("before its first logged iteration");
  const std::string resume = s.checkpoint > 0 ? fmt::format("resumes from chkpnt{}.bin", s.checkpoint)
                                              : std::string("restarts from scratch (no checkpoint)");
  switch (s.phase) {
    case RunPhase::Pending: return "pending";
    case RunPhase::Finished:
      if (!s.differs.empty()) return "finished with another configuration: " + s.differs;
      if (!s.message.empty()) return "finished (" + s.message + ")";
      return fmt::format("finished: PSNR {:.3f}, SSIM {:.4f}, {} Gaussians, {:.0f} s", s.psnr, s.ssim, s.gaussians,
                         s.train_seconds);
    case RunPhase::Running: {
      std::string line = fmt::format("running (pid {}): iteration {}/{}", s.pid, s.iteration, s.iterations);
      if (s.iteration > 0) {
        line += " after " + format_duration(s.elapsed_s);
        if (s.iterations > s.iteration)
          line += ", about " + format_duration(s.elapsed_s / s.iteration * (s.iterations - s.iteration)) +
                  " left at the mean pace so far";
      }
      return line;
    }
    case RunPhase::Interrupted: return fmt::format("interrupted {}; {}", at, resume);
    case RunPhase::Failed: return fmt::format("failed {}: {}", at, s.message);
  }
  return "?";
}

}  // namespace d2gs::experiment
