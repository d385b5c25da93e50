#include <gtest/gtest.h>

#include <string>

#include "d2gs/core/stage_profile.hpp"

namespace d2gs::profile {
namespace {

// Restores the process's setting (D2GS_PROFILE may be set for the whole test run) and empties the totals.
class StageProfile : public ::testing::Test {
protected:
  void SetUp() override {
    was_ = enabled();
    reset();
  }
  void TearDown() override {
    set_enabled(was_);
    reset();
  }
  bool was_ = false;
};

TEST_F(StageProfile, OffRecordsNothing) {
  set_enabled(false);
  { const Scope s("a"); }
  EXPECT_TRUE(totals().empty());
  EXPECT_EQ(format_table(totals(), "step"), "");
}

TEST_F(StageProfile, SumsCallsInFirstRecordedOrderAndPausedStopsRecording) {
  set_enabled(true);
  record("step", 1.0);
  record("b", 0.25);
  record("a", 0.125);
  record("b", 0.25);
  record("step", 1.0);
  {
    const Scope outer("c");
    const Paused inside;
    EXPECT_FALSE(enabled());
    { const Scope hidden("hidden"); }
  }
  EXPECT_TRUE(enabled());
  const auto t = totals();
  ASSERT_EQ(t.size(), 4u);
  EXPECT_EQ(t[0].stage, "step");
  EXPECT_DOUBLE_EQ(t[0].seconds, 2.0);
  EXPECT_EQ(t[0].calls, 2);
  EXPECT_EQ(t[1].stage, "b");
  EXPECT_DOUBLE_EQ(t[1].seconds, 0.5);
  EXPECT_EQ(t[1].calls, 2);
  EXPECT_EQ(t[2].stage, "a");
  EXPECT_EQ(t[3].stage, "c");  // recorded by its own scope after the pause ended; "hidden" never
  EXPECT_EQ(t[3].calls, 1);
  EXPECT_GE(t[3].seconds, 0.0);
}

TEST_F(StageProfile, TableGivesMillisecondsPerWholeCallAndTheUncoveredRest) {
  set_enabled(true);
  record("step", 0.5);
  record("step", 0.5);
  record("render / part", 0.125);  // a part: listed under render, not added to the covered time
  record("render", 0.25);
  record("loss", 0.5);
  const std::string table = format_table(totals(), "step");
  // per call of step: render 125 ms (25 %), loss 250 ms (50 %), other 125 ms (25 %), step 500 ms.
  EXPECT_NE(table.find("render"), std::string::npos);
  EXPECT_NE(table.find("125.000"), std::string::npos) << table;
  EXPECT_NE(table.find("250.000"), std::string::npos) << table;
  EXPECT_NE(table.find("500.000"), std::string::npos) << table;
  EXPECT_NE(table.find("25.0%"), std::string::npos) << table;
  EXPECT_NE(table.find("50.0%"), std::string::npos) << table;
  EXPECT_NE(table.find("other"), std::string::npos) << table;
  EXPECT_NE(table.find("  part"), std::string::npos) << table;
  EXPECT_NE(table.find("62.500"), std::string::npos) << table;  // the part, per call of step
  EXPECT_LT(table.find("render"), table.find("  part")) << table;
  EXPECT_LT(table.find("  part"), table.find("loss")) << table;
  EXPECT_EQ(format_table(totals(), "absent"), "");
}

}  // namespace
}  // namespace d2gs::profile
