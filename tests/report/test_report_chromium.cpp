// The report in a real browser: headless Chromium loads the page, runs its image check and dumps the
// DOM. Skipped (with a message) where /usr/bin/chromium is absent; scripts/setup.sh installs it.
#include <gtest/gtest.h>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/report/run_report.hpp"
#include "fake_run.hpp"
#include "report/chromium.hpp"
#include "test_paths.hpp"

namespace d2gs::report {
namespace {
namespace fs = std::filesystem;
using test::kChromium;
using test::Loaded;
using test::load;
using test::page_errors;

TEST(ReportChromium, RunReportLoadsWithEveryImageDecoded) {
  if (!fs::exists(kChromium)) GTEST_SKIP() << kChromium << " not installed (scripts/setup.sh installs chromium)";
  const auto dir = test::scratch_dir();
  test::make_fake_run(dir / "run");
  const fs::path page = write_run_report(dir / "run");
  const Loaded loaded = load(page, dir / "profile");
  const std::string& dom = loaded.dom;
  ASSERT_NE(dom.find("</html>"), std::string::npos) << "chromium produced no DOM";
  for (const char* id : {"summary", "metrics", "curves", "views", "layers", "imr"})
    EXPECT_NE(dom.find(std::string("id=\"") + id + "\""), std::string::npos) << id;
  EXPECT_NE(dom.find("data-images-ok=\"6\""), std::string::npos) << "the page's image check did not pass";
  EXPECT_EQ(dom.find("id=\"load-error\""), std::string::npos);
  EXPECT_EQ(page_errors(loaded.log), "");
}

TEST(ReportChromium, BrokenImageIsFlagged) {
  if (!fs::exists(kChromium)) GTEST_SKIP() << kChromium << " not installed (scripts/setup.sh installs chromium)";
  const auto dir = test::scratch_dir();
  HtmlPage page("broken");
  page.add_section("views", "Views", "<img src=\"data:image/png;base64,AAAAAAAA\" alt=\"bad one\">\n");
  write_file_atomic(dir / "broken.html", page.str());
  const std::string dom = load(dir / "broken.html", dir / "profile").dom;
  EXPECT_NE(dom.find("id=\"load-error\""), std::string::npos) << dom.substr(0, 2000);
  EXPECT_NE(dom.find("bad one"), std::string::npos);
}

// The console check is not vacuous: a script error on the page shows in the log.
TEST(ReportChromium, ScriptErrorIsSeen) {
  if (!fs::exists(kChromium)) GTEST_SKIP() << kChromium << " not installed (scripts/setup.sh installs chromium)";
  const auto dir = test::scratch_dir();
  HtmlPage page("throws");
  page.add_section("s", "S", "<script>throw new Error('report test boom');</script>\n");
  write_file_atomic(dir / "throws.html", page.str());
  const Loaded loaded = load(dir / "throws.html", dir / "profile");
  EXPECT_NE(page_errors(loaded.log).find("report test boom"), std::string::npos) << loaded.log.substr(0, 4000);
}

}  // namespace
}  // namespace d2gs::report
