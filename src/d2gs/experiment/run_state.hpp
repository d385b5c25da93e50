#pragma once
// Where a run of an experiment stands, read from its folder without touching it (`d2gs experiment
// --list`): finished (results.json, with its scores), running (a live process holds the run's lock),
// failed (its log ends with the program's error line), interrupted (a log but neither), or pending (no
// log). Running or interrupted runs report their last logged iteration from train_log.jsonl and the
// checkpoint a resume would start from.
//
// "Running" is judged by the process id the lock's last holder wrote into DIR/logs/ID.lock being alive on
// this machine: the lock itself is never taken (that would make a runner starting at the same instant
// skip the run as busy). A runner on another machine of a shared file system, or a recycled process id,
// is not told apart.
#include <filesystem>
#include <string>
#include <vector>

#include "d2gs/experiment/experiment_config.hpp"

namespace d2gs::experiment {

enum class RunPhase { Pending, Running, Interrupted, Failed, Finished };
const char* to_string(RunPhase p);

struct RunState {
  RunPhase phase = RunPhase::Pending;
  int iteration = 0;       // the last iteration train_log.jsonl logged (0: none)
  int iterations = 0;      // the iterations the run trains to
  double elapsed_s = 0;    // training seconds at `iteration` (resumed runs count their earlier time)
  int checkpoint = 0;      // the newest chkpntN.bin in the run folder (0: none); not read here
  long pid = 0;            // running: the process holding the run's lock
  double psnr = 0, ssim = 0, train_seconds = 0;  // finished: results.json's mean test scores and time
  long gaussians = 0;                           // finished: the model's size
  std::string message;  // failed: the log's error line; finished: why results.json could not be read
  std::string differs;  // finished: how it was trained otherwise than the experiment now says (empty: it was not)
};

// `ended_holder`: a process id known to hold no run any more, not taken as running (the runner's own, when
// its report inspects the runs after they ended; 0: none).
RunState inspect_run(const std::filesystem::path& out_dir, const RunSpec& run, long ended_holder = 0);

// Empty when the finished run in `out_dir / run.dir` was trained as the experiment now configures it (every
// option but the output-only ones, paths absolute: train/checkpoint.hpp's identity_options); else the first
// difference, e.g. "opacity_lr was 0.05, the experiment now gives 0.1". A run whose config.json cannot be read
// says so. Changing a method's options under the same variant name would otherwise count the old results as
// the new configuration's.
std::string finished_run_differs(const std::filesystem::path& out_dir, const RunSpec& run);

// Fails with a one-line error naming the first finished run of `runs` that finished_run_differs, before
// anything is trained or tabulated.
void check_finished_runs_match(const std::filesystem::path& out_dir, const std::vector<RunSpec>& runs);

// One line, e.g. "finished: PSNR 23.207, SSIM 0.7624, 69531 Gaussians, 2532 s" or "running (pid 812):
// iteration 5000/10000 after 22:02, about 22:02 left at the mean pace so far".
std::string describe(const RunState& state);

}  // namespace d2gs::experiment
