// The report in a real browser: headless Chromium loads the page, runs its image check and dumps the
// DOM. Skipped (with a message) where /usr/bin/chromium is absent; scripts/setup.sh installs it.
#include <cstdio>
#include <cstdlib>

#include <gtest/gtest.h>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/report/run_report.hpp"
#include "fake_run.hpp"
#include "test_paths.hpp"

namespace d2gs::report {
namespace {
namespace fs = std::filesystem;

constexpr const char* kChromium = "/usr/bin/chromium";

// The DOM after load, as Chromium serialises it, and what Chromium logged (console messages included).
// Headless needs no display; `timeout` bounds a hung browser (no DOM then, and the test fails).
struct Loaded {
  std::string dom;
  std::string log;
};

Loaded load(const fs::path& page, const fs::path& profile) {
  const fs::path log = profile.string() + ".log";
  const std::string cmd = "timeout -k 10 90 " + std::string(kChromium) +
                          " --headless --no-sandbox --disable-gpu --disable-quic --no-first-run"
                          " --disable-background-networking --disable-component-update --disable-sync"
                          " --enable-logging=stderr --v=0"
                          " --user-data-dir='" + profile.string() + "' --dump-dom 'file://" + page.string() +
                          "' 2>'" + log.string() + "' </dev/null";
  Loaded out;
  FILE* pipe = ::popen(cmd.c_str(), "r");
  if (!pipe) return out;
  char buffer[65536];
  std::size_t n;
  while ((n = std::fread(buffer, 1, sizeof buffer, pipe)) > 0) out.dom.append(buffer, n);
  ::pclose(pipe);
  if (fs::exists(log)) out.log = read_file(log);
  return out;
}

// Console lines that mean the page itself went wrong (a script error, a resource that did not load).
std::string page_errors(const std::string& log) {
  std::string bad;
  std::size_t start = 0;
  while (start < log.size()) {
    std::size_t end = log.find('\n', start);
    if (end == std::string::npos) end = log.size();
    const std::string line = log.substr(start, end - start);
    if (line.find("CONSOLE") != std::string::npos &&
        (line.find("Uncaught") != std::string::npos || line.find("Failed to load") != std::string::npos ||
         line.find("Refused") != std::string::npos))
      bad += line + "\n";
    start = end + 1;
  }
  return bad;
}

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
