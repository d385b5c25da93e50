#pragma once
// The progress line of `d2gs train` on stderr: iteration, iterations per second, a smoothed loss, the
// Gaussian count, the elapsed time and an ETA. On a terminal one line, rewritten at most four times a
// second; elsewhere (a log file) one line per tenth of the run. Nothing with --quiet.
#include <chrono>
#include <cstddef>
#include <string>

namespace d2gs {

// "mm:ss", or "h:mm:ss" from an hour on; "--:--" when not a finite non-negative number.
std::string format_duration(double seconds);

class TrainingProgress {
public:
  // `start`: the iteration the run goes on from (0, or a checkpoint's).
  TrainingProgress(std::string method, int start, int iterations, bool quiet);
  // After iteration `t`: its loss, the model's size and the run's seconds so far (before a resume too).
  void update(int t, double loss, std::size_t gaussians, double elapsed_s);
  // Ends the terminal's line once the loop is done.
  void finish() const;

private:
  using Clock = std::chrono::steady_clock;
  std::string method_;
  int start_, iterations_;
  bool quiet_, tty_;
  Clock::time_point t0_, last_print_;
  int last_decile_ = -1;
  double ema_loss_ = 0.0;
};

}  // namespace d2gs
