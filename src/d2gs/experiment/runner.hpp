#pragma once
// Runs an experiment's training runs on this machine: each run is a child process of the same d2gs
// program (`d2gs train --config DIR/configs/ID.json [--resume chkpntN.bin]`, output to DIR/logs/ID.log),
// up to `jobs` at a time. A run with results.json is finished and skipped; a run folder with a
// checkpoint resumes from its latest one that reads back whole (a damaged newer one is passed over, and
// the log says so); a run folder without one starts again from scratch. A failed run is reported and
// does not stop the others. A per-run lock file (core/file_lock.hpp) keeps two runners (two local
// invocations, or a requeued Slurm task) from training the same run at once.
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "d2gs/experiment/experiment_config.hpp"

namespace d2gs::experiment {

enum class RunStatus { Finished, Skipped, Failed, Busy };
const char* to_string(RunStatus s);

struct RunOutcome {
  int index = 0;
  std::string id;
  RunStatus status = RunStatus::Failed;
  int resumed_from = 0;  // checkpoint iteration, 0 for a fresh start
  double seconds = 0;
  std::string message;  // for a failure: the last error line of its log
};

struct RunnerOptions {
  int jobs = 1;
  bool keep_checkpoints = false;  // else chkpnt*.bin are deleted once a run has results.json
  std::filesystem::path program;  // the d2gs program (default: this process's own executable)
  std::function<void(const std::string&)> progress;  // one line per started/finished run
};

// True when the run's folder holds results.json.
bool run_finished(const std::filesystem::path& out_dir, const RunSpec& run);
// The highest chkpntN.bin (N ≤ max_iteration) in `run_dir` that reads back whole (format, size, CRC-32),
// with N; the reasons the higher ones could not be used are appended to `unusable`.
std::optional<std::pair<int, std::filesystem::path>> usable_checkpoint(const std::filesystem::path& run_dir,
                                                                       int max_iteration,
                                                                       std::vector<std::string>* unusable = nullptr);
// Runs the given runs (skipping finished ones) and returns one outcome per run, in run order.
std::vector<RunOutcome> run_all(const std::vector<RunSpec>& runs, const std::filesystem::path& out_dir,
                                const RunnerOptions& options);

// DIR/experiment.json: the experiment (scene sources made absolute) and its run list, so that
// `--run-index` tasks and `collect` see the same runs. Written atomically.
void write_experiment_state(const std::filesystem::path& out_dir, const ExperimentConfig& config,
                            const std::vector<RunSpec>& runs);
// Reads DIR/experiment.json back into a configuration and its run list.
std::pair<ExperimentConfig, std::vector<RunSpec>> read_experiment_state(const std::filesystem::path& out_dir);

}  // namespace d2gs::experiment
