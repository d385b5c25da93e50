#include "d2gs/core/interrupt.hpp"

#include <unistd.h>

#include <atomic>
#include <csignal>

namespace d2gs {
namespace {

std::atomic<int> received{0};
struct sigaction previous_int {}, previous_term {};

extern "C" void on_signal(int signal) {
  received.store(signal, std::memory_order_relaxed);
  // The default action from now on: a second signal ends the process at once.
  struct sigaction dfl {};
  dfl.sa_handler = SIG_DFL;
  sigemptyset(&dfl.sa_mask);
  sigaction(signal, &dfl, nullptr);
  const char msg[] = "\nd2gs: stopping at the next step (the same signal again stops at once)\n";
  [[maybe_unused]] const auto n = ::write(STDERR_FILENO, msg, sizeof msg - 1);
}

}  // namespace

InterruptScope::InterruptScope() {
  received.store(0, std::memory_order_relaxed);
  struct sigaction action {};
  action.sa_handler = on_signal;
  sigemptyset(&action.sa_mask);
  action.sa_flags = 0;  // no SA_RESTART: a blocking wait returns EINTR and can look at the flag
  sigaction(SIGINT, &action, &previous_int);
  sigaction(SIGTERM, &action, &previous_term);
  // A signal the process was started ignoring (a background job of a script, nohup) stays ignored.
  if (previous_int.sa_handler == SIG_IGN) sigaction(SIGINT, &previous_int, nullptr);
  if (previous_term.sa_handler == SIG_IGN) sigaction(SIGTERM, &previous_term, nullptr);
}

InterruptScope::~InterruptScope() {
  sigaction(SIGINT, &previous_int, nullptr);
  sigaction(SIGTERM, &previous_term, nullptr);
}

int interrupt_signal() { return received.load(std::memory_order_relaxed); }

void check_interrupted(const char* where) {
  if (const int s = interrupt_signal(); s != 0)
    throw Interrupted(fmt::format("interrupted by {} {}", s == SIGINT ? "SIGINT" : s == SIGTERM ? "SIGTERM" : "a signal", where));
}

}  // namespace d2gs
