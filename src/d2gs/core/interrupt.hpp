#pragma once
// Ctrl-C (SIGINT) and SIGTERM as an exception at the next check: while an InterruptScope lives, the first
// such signal only sets a flag (and says so on stderr), and the command's next check_interrupted() throws
// Interrupted, so that its destructors run: partial output sets are taken back (core/atomic_file.hpp,
// OutputSet), temporaries removed, locks released. The signal's default action is restored at once, so
// a second one ends the process where it stands. `d2gs` exits 130 (128 + SIGINT) on Interrupted.
//
// Checks sit in the serial parts of the long loops (training iterations, rendered and scored views, the
// geometry's steps, Sinkhorn iterations, the experiment runner's wait), never inside OpenMP regions.
#include "d2gs/core/error.hpp"

namespace d2gs {

class Interrupted : public Error {
public:
  using Error::Error;
};

class InterruptScope {
public:
  InterruptScope();   // installs the handlers (and clears an earlier interrupt)
  ~InterruptScope();  // restores the previous dispositions
  InterruptScope(const InterruptScope&) = delete;
  InterruptScope& operator=(const InterruptScope&) = delete;
};

// The signal received while a scope was live (SIGINT or SIGTERM), else 0.
int interrupt_signal();
// Throws Interrupted ("interrupted by SIGINT ...") once a signal was received; `where` says what stopped.
void check_interrupted(const char* where);

}  // namespace d2gs
