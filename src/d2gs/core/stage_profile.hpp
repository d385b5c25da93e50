#pragma once
// Wall-clock time per stage of training, summed over a run: where an iteration's time goes at the thread
// count it runs with (callgrind's instruction counts say what each stage executes, not how well it runs in
// parallel). Off unless the environment sets D2GS_PROFILE (any value but "" or "0"), or a program calls
// set_enabled(true); when off a Scope costs one test of a flag. The stages are timed on the thread that
// calls them, outside parallel regions; the Trainer names them (docs/benchmarks.md, "Training iteration").
#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

namespace d2gs::profile {

bool enabled();
void set_enabled(bool on);

// Adds `seconds` to the stage's total and counts one call. Stages keep the order of their first record.
void record(const char* stage, double seconds);

// Times its own lifetime as one call of `stage` (a string literal: kept by pointer).
class Scope {
public:
  explicit Scope(const char* stage) : stage_(enabled() ? stage : nullptr) {
    if (stage_) start_ = std::chrono::steady_clock::now();
  }
  ~Scope() {
    if (stage_) record(stage_, std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count());
  }
  Scope(const Scope&) = delete;
  Scope& operator=(const Scope&) = delete;

private:
  const char* stage_;
  std::chrono::steady_clock::time_point start_{};
};

// Stops recording for its lifetime (work inside a stage that is not a stage of its own, such as the test
// renders of a training step, whose render stages would otherwise count as training's).
class Paused {
public:
  Paused() : was_(enabled()) { set_enabled(false); }
  ~Paused() { set_enabled(was_); }
  Paused(const Paused&) = delete;
  Paused& operator=(const Paused&) = delete;

private:
  bool was_;
};

struct StageTotal {
  std::string stage;
  double seconds = 0.0;
  std::int64_t calls = 0;
};

std::vector<StageTotal> totals();
void reset();

// A table of the stages nested in `whole` (every other stage): milliseconds per call of `whole`, share of
// it, and "other" for the part of `whole` no stage covers. A stage named "A / B" is a part of stage A,
// listed under it and not counted twice. Empty when `whole` was never recorded.
std::string format_table(const std::vector<StageTotal>& stages, const std::string& whole);

}  // namespace d2gs::profile
