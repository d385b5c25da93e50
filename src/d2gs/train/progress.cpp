#include "d2gs/train/progress.hpp"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <utility>

#include <fmt/format.h>

namespace d2gs {

std::string format_duration(double seconds) {
  if (!std::isfinite(seconds) || seconds < 0) return "--:--";
  const long s = std::lround(seconds);
  if (s >= 3600) return fmt::format("{}:{:02}:{:02}", s / 3600, (s / 60) % 60, s % 60);
  return fmt::format("{:02}:{:02}", s / 60, s % 60);
}

TrainingProgress::TrainingProgress(std::string method, int start, int iterations, bool quiet)
    : method_(std::move(method)),
      start_(start),
      iterations_(iterations),
      quiet_(quiet),
      tty_(::isatty(STDERR_FILENO) != 0),
      t0_(Clock::now()),
      last_print_(t0_) {}

void TrainingProgress::update(int t, double loss, std::size_t gaussians, double elapsed_s) {
  ema_loss_ = t == start_ + 1 ? loss : 0.6 * loss + 0.4 * ema_loss_;
  if (quiet_) return;
  const auto now = Clock::now();
  const double secs = std::chrono::duration<double>(now - t0_).count();
  const double rate = (t - start_) / std::max(secs, 1e-9);
  const double eta = (iterations_ - t) / std::max(rate, 1e-9);
  const std::string line = fmt::format("[train {}] it {}/{}  {:.1f} it/s  loss {:.4f}  #G {}  elapsed {}  ETA {}",
                                       method_, t, iterations_, rate, ema_loss_, gaussians,
                                       format_duration(elapsed_s), format_duration(eta));
  if (tty_ && (std::chrono::duration<double>(now - last_print_).count() > 0.25 || t == iterations_)) {
    std::fprintf(stderr, "\r%s\033[K", line.c_str());
    last_print_ = now;
  } else if (!tty_) {
    const int decile = static_cast<int>(10.0 * t / iterations_);
    if (decile != last_decile_) {
      std::fprintf(stderr, "%s\n", line.c_str());
      last_decile_ = decile;
    }
  }
}

void TrainingProgress::finish() const {
  if (!quiet_ && tty_) std::fprintf(stderr, "\n");
}

}  // namespace d2gs
