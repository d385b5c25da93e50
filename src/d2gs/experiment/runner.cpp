#include "d2gs/experiment/runner.hpp"

#include <fcntl.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstring>
#include <fstream>
#include <map>
#include <thread>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/interrupt.hpp"
#include "d2gs/core/json_value.hpp"
#include "d2gs/core/file_lock.hpp"
#include "d2gs/core/log.hpp"
#include "d2gs/train/checkpoint.hpp"

extern char** environ;

namespace d2gs::experiment {
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

const char* to_string(RunStatus s) {
  switch (s) {
    case RunStatus::Finished: return "finished";
    case RunStatus::Skipped: return "skipped (already finished)";
    case RunStatus::Failed: return "FAILED";
    case RunStatus::Busy: return "skipped (another runner holds it)";
  }
  return "?";
}

bool run_finished(const fs::path& out_dir, const RunSpec& run) {
  return fs::is_regular_file(out_dir / run.dir / "results.json");
}

std::optional<std::pair<int, fs::path>> usable_checkpoint(const fs::path& run_dir, int max_iteration,
                                                          std::vector<std::string>* unusable) {
  std::error_code ec;
  if (!fs::is_directory(run_dir, ec)) return std::nullopt;
  for (const auto& [iteration, path] : checkpoints_in(run_dir)) {
    if (iteration > max_iteration) continue;
    try {
      (void)read_checkpoint(path);  // magic, format, size, CRC-32 and array shapes
      return std::make_pair(iteration, path);
    } catch (const Error& e) {
      if (unusable) unusable->push_back(e.what());
    }
  }
  return std::nullopt;
}

namespace {

// The last line of a log that reads like an error, else its last non-empty line.
std::string last_error_line(const fs::path& log) {
  std::error_code ec;
  if (!fs::is_regular_file(log, ec)) return "";  // a named pipe would block the open
  std::ifstream in(log);
  std::string line, last, error;
  while (std::getline(in, line)) {
    if (line.empty()) continue;
    last = line;
    if (line.find("error") != std::string::npos) error = line;
  }
  return error.empty() ? last : error;
}

struct Child {
  std::size_t slot = 0;  // position in the run list
  FileLock lock;         // the run's lock, held while its process runs
  Clock::time_point started;
};

// Starts `argv` with stdout and stderr appended to `log`; the child dies with its parent.
pid_t spawn(const std::vector<std::string>& args, const std::vector<std::string>& env, const fs::path& log) {
  std::vector<char*> argv, envp;
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  for (const auto& e : env) envp.push_back(const_cast<char*>(e.c_str()));
  envp.push_back(nullptr);
  const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  if (fd < 0) fail_file(log, "cannot open for writing ({})", std::strerror(errno));
  const pid_t parent = ::getpid();
  const pid_t pid = ::fork();
  if (pid < 0) {
    ::close(fd);
    fail("experiment: fork failed ({})", std::strerror(errno));
  }
  if (pid == 0) {
    ::prctl(PR_SET_PDEATHSIG, SIGTERM);
    if (::getppid() != parent) ::_exit(125);
    const int null_in = ::open("/dev/null", O_RDONLY);
    if (null_in >= 0) ::dup2(null_in, STDIN_FILENO);
    ::dup2(fd, STDOUT_FILENO);
    ::dup2(fd, STDERR_FILENO);
    ::execve(argv[0], argv.data(), envp.data());
    const char msg[] = "d2gs: error: experiment: cannot execute the d2gs program\n";
    [[maybe_unused]] const auto n = ::write(STDERR_FILENO, msg, sizeof msg - 1);
    ::_exit(127);
  }
  ::close(fd);
  return pid;
}

}  // namespace

std::vector<RunOutcome> run_all(const std::vector<RunSpec>& runs, const fs::path& out_dir, const RunnerOptions& options) {
  const fs::path root = fs::absolute(out_dir);
  const fs::path program = options.program.empty() ? fs::read_symlink("/proc/self/exe") : options.program;
  const int jobs = std::max(1, options.jobs);
  const auto say = [&](const std::string& line) {
    if (options.progress) options.progress(line);
  };
  fs::create_directories(root / "logs");
  fs::create_directories(root / "configs");

  // Environment of the children: ours, with the OpenMP threads shared out between parallel jobs.
  std::vector<std::string> env;
  bool has_omp = false;
  for (char** e = environ; e && *e; ++e) {
    env.emplace_back(*e);
    has_omp = has_omp || env.back().rfind("OMP_NUM_THREADS=", 0) == 0;
  }
  if (!has_omp && jobs > 1) {
    const unsigned hw = std::max(1u, std::thread::hardware_concurrency());
    env.push_back(fmt::format("OMP_NUM_THREADS={}", std::max(1u, hw / static_cast<unsigned>(jobs))));
  }

  std::vector<RunOutcome> outcomes(runs.size());
  std::vector<std::size_t> todo;
  for (std::size_t k = 0; k < runs.size(); ++k) {
    outcomes[k].index = runs[k].index;
    outcomes[k].id = runs[k].id();
    if (run_finished(root, runs[k])) {
      outcomes[k].status = RunStatus::Skipped;
      say(fmt::format("run {} {}: skipped, already finished", runs[k].index, runs[k].id()));
    } else {
      todo.push_back(k);
    }
  }

  std::map<pid_t, Child> running;
  std::size_t next = 0;
  std::size_t done = 0;
  const auto launch = [&](std::size_t k) {
    const RunSpec& run = runs[k];
    RunOutcome& out = outcomes[k];
    const fs::path log = root / "logs" / (run.id() + ".log");
    const fs::path lock = root / "logs" / (run.id() + ".lock");
    std::optional<FileLock> lock_held = FileLock::try_acquire(lock);
    if (!lock_held) {
      out.status = RunStatus::Busy;
      say(fmt::format("run {} {}: skipped, another runner is training it", run.index, run.id()));
      return;
    }
    // Checked again under the lock: another runner may have finished it meanwhile.
    if (run_finished(root, run)) {
      out.status = RunStatus::Skipped;
      return;
    }
    const fs::path run_dir = root / run.dir;
    const fs::path config = root / "configs" / (run.id() + ".json");
    write_file_atomic(config, run.train_config.dump(2) + "\n");
    std::vector<std::string> args = {program.string(), "train", "--config", config.string()};
    const int iterations = run.train_config.at("iterations").get<int>();
    std::string how = "starting";
    // The newest checkpoint that reads back whole: a damaged newer one (a full disk, a crash of the
    // machine) is passed over, and rewritten when the resumed run reaches its iteration again.
    std::vector<std::string> unusable;
    const auto ckpt = usable_checkpoint(run_dir, iterations, &unusable);
    const std::string passed_over =
        unusable.empty() ? "" : fmt::format("; passed over {}", fmt::join(unusable, "; "));
    if (ckpt) {
      args.insert(args.end(), {"--resume", ckpt->second.string()});
      out.resumed_from = ckpt->first;
      how = fmt::format("resuming from {}{}", ckpt->second.filename().string(), passed_over);
    } else if (fs::exists(run_dir)) {
      // Killed before its first checkpoint, or no checkpoint reads back: nothing to continue from.
      fs::remove_all(run_dir);
      how = unusable.empty() ? "restarting (no checkpoint left by the previous attempt)"
                             : fmt::format("restarting (no usable checkpoint{})", passed_over);
    }
    fs::create_directories(run_dir.parent_path());
    {
      std::ofstream header(log, std::ios::app);
      header << fmt::format("==== d2gs experiment: run {} {}, {} ====\n", run.index, run.id(), how);
    }
    say(fmt::format("run {} {}: {} (log: {})", run.index, run.id(), how, log.string()));
    try {
      const pid_t pid = spawn(args, env, log);
      running.emplace(pid, Child{k, std::move(*lock_held), Clock::now()});
    } catch (const Error& e) {
      out.status = RunStatus::Failed;
      out.message = e.what();
      say(fmt::format("run {} {}: FAILED to start: {}", run.index, run.id(), e.what()));
    }
  };

  // Interrupted: no run is started any more, the running ones are asked to stop (SIGTERM: they stop at their
  // next iteration, resumable from their checkpoints) and waited for, then the runner stops too.
  bool stopping = false;
  while (next < todo.size() || !running.empty()) {
    if (interrupt_signal() != 0 && !stopping) {
      stopping = true;
      next = todo.size();
      for (const auto& [child_pid, child] : running) ::kill(child_pid, SIGTERM);
      say(fmt::format("interrupted: stopping the {} running run(s)", running.size()));
    }
    while (static_cast<int>(running.size()) < jobs && next < todo.size()) launch(todo[next++]);
    if (running.empty()) continue;
    int status = 0;
    const pid_t pid = ::waitpid(-1, &status, 0);
    if (pid < 0) {
      if (errno == EINTR) continue;
      fail("experiment: waiting for runs failed ({})", std::strerror(errno));
    }
    const auto it = running.find(pid);
    if (it == running.end()) continue;
    const Child child = std::move(it->second);
    running.erase(it);
    const RunSpec& run = runs[child.slot];
    RunOutcome& out = outcomes[child.slot];
    out.seconds = std::chrono::duration<double>(Clock::now() - child.started).count();
    const fs::path log = root / "logs" / (run.id() + ".log");
    const bool ok = WIFEXITED(status) && WEXITSTATUS(status) == 0 && run_finished(root, run);
    ++done;
    if (ok) {
      out.status = RunStatus::Finished;
      const auto metrics = [&]() -> std::string {
        try {
          const auto j = nlohmann::json::parse(read_file(root / run.dir / "results.json"));
          return fmt::format("PSNR {:.3f}, SSIM {:.4f}", j.at("mean").at("PSNR").get<double>(),
                             j.at("mean").at("SSIM").get<double>());
        } catch (const std::exception&) {
          return "results.json written";
        }
      }();
      if (!options.keep_checkpoints) {
        // Checkpoints served their purpose once results.json exists.
        std::error_code ec;
        for (const auto& [iteration, path] : checkpoints_in(root / run.dir)) fs::remove(path, ec);
      }
      say(fmt::format("run {} {}: finished in {:.1f} s ({})", run.index, run.id(), out.seconds, metrics));
    } else {
      out.status = RunStatus::Failed;
      const std::string why = WIFSIGNALED(status) ? fmt::format("killed by signal {}", WTERMSIG(status))
                                                  : fmt::format("exit code {}", WEXITSTATUS(status));
      out.message = why + ": " + last_error_line(log);
      say(fmt::format("run {} {}: FAILED ({}); log: {}", run.index, run.id(), out.message, log.string()));
    }
  }  // the run's lock is released with `child`
  if (stopping) check_interrupted("(the unfinished runs resume from their checkpoints when the experiment is run again)");
  return outcomes;
}

void write_experiment_state(const fs::path& out_dir, const ExperimentConfig& config, const std::vector<RunSpec>& runs) {
  // The folder's own copy of the configuration is read back without a data root (sources are stored
  // absolute), so relative initial clouds are stored absolute too.
  nlohmann::json raw = config.raw;
  raw.erase("data_root");
  const auto absolute_init = [&](nlohmann::json& options) {
    if (options.is_object() && options.contains("init") && options["init"].is_string())
      options["init"] = resolve_init_path(options["init"].get<std::string>(), config.data_root);
  };
  if (raw.contains("train")) absolute_init(raw["train"]);
  if (raw.contains("methods") && raw["methods"].is_array())
    for (auto& m : raw["methods"])
      if (m.contains("options")) absolute_init(m["options"]);
  for (std::size_t k = 0; k < config.scenes.size() && k < raw["scenes"].size(); ++k) {
    raw["scenes"][k]["source"] = config.scenes[k].source;
    raw["scenes"][k]["name"] = config.scenes[k].name;
  }
  nlohmann::json list = nlohmann::json::array();
  for (const auto& r : runs)
    list.push_back({{"index", r.index}, {"id", r.id()}, {"dir", r.dir.string()}, {"scene", r.scene},
                    {"views", r.views}, {"method", r.label}, {"seed", r.seed}});
  const nlohmann::json state = {{"format", "d2gs-experiment-1"},
                                {"config_file", fs::absolute(config.file).string()},
                                {"config", raw},
                                {"runs", list}};
  fs::create_directories(out_dir);
  write_file_atomic(out_dir / "experiment.json", state.dump(2) + "\n");
}

std::pair<ExperimentConfig, std::vector<RunSpec>> read_experiment_state(const fs::path& out_dir) {
  const fs::path file = out_dir / "experiment.json";
  if (!fs::is_regular_file(file))
    fail_file(out_dir, "holds no experiment.json (run `d2gs experiment --config EXP.json -o DIR` first)");
  const nlohmann::json state = read_json_file(file);
  if (!state.is_object() || state.value("format", "") != "d2gs-experiment-1" || !state.contains("config"))
    fail_file(file, "not a d2gs experiment state file");
  ExperimentConfig config = parse_experiment_config(state["config"], file);
  std::vector<RunSpec> runs = expand_runs(config, out_dir);
  return {std::move(config), std::move(runs)};
}

}  // namespace d2gs::experiment
