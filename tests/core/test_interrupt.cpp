// core/interrupt.hpp: the first SIGINT or SIGTERM inside a scope becomes an Interrupted exception at the
// next check (the second ends the process: its default action is back), and the scope restores the
// dispositions it found, an ignored signal staying ignored.
#include <csignal>
#include <string>

#include <gtest/gtest.h>

#include "d2gs/core/interrupt.hpp"

namespace d2gs {
namespace {

void (*disposition(int signal))(int) {
  struct sigaction now {};
  sigaction(signal, nullptr, &now);
  return now.sa_handler;
}

TEST(Interrupt, TheFirstSignalBecomesAnExceptionAtTheNextCheck) {
  // From the default actions, whatever the test runner was started with (a background job ignores SIGINT).
  const auto saved_int = std::signal(SIGINT, SIG_DFL), saved_term = std::signal(SIGTERM, SIG_DFL);
  {
    const InterruptScope scope;
    EXPECT_NO_THROW(check_interrupted("before"));
    EXPECT_NE(disposition(SIGINT), SIG_DFL);
    std::raise(SIGINT);  // returns: the handler only sets the flag
    EXPECT_EQ(interrupt_signal(), SIGINT);
    EXPECT_EQ(disposition(SIGINT), SIG_DFL);   // a second Ctrl-C would end the process now
    EXPECT_NE(disposition(SIGTERM), SIG_DFL);  // the other signal is still caught
    try {
      check_interrupted("at iteration 7 of 10");
      ADD_FAILURE() << "no exception";
    } catch (const Interrupted& e) {
      EXPECT_EQ(std::string(e.what()), "interrupted by SIGINT at iteration 7 of 10");
    }
    EXPECT_THROW(check_interrupted("again"), Error);  // Interrupted is an Error: every handler of errors unwinds
  }
  EXPECT_EQ(disposition(SIGINT), SIG_DFL);
  EXPECT_EQ(disposition(SIGTERM), SIG_DFL);
  {
    const InterruptScope fresh;  // a new scope starts clear
    EXPECT_EQ(interrupt_signal(), 0);
    std::raise(SIGTERM);
    EXPECT_THROW(check_interrupted("x"), Interrupted);
  }
  std::signal(SIGINT, saved_int);
  std::signal(SIGTERM, saved_term);
}

TEST(Interrupt, AnIgnoredSignalStaysIgnored) {
  const auto previous = std::signal(SIGINT, SIG_IGN);  // as a script's background job starts
  {
    const InterruptScope scope;
    EXPECT_EQ(disposition(SIGINT), SIG_IGN);
    std::raise(SIGINT);
    EXPECT_EQ(interrupt_signal(), 0);
    EXPECT_NO_THROW(check_interrupted("x"));
  }
  EXPECT_EQ(disposition(SIGINT), SIG_IGN);
  std::signal(SIGINT, previous);
}

}  // namespace
}  // namespace d2gs
