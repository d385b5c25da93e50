// The report in a real browser: headless Chromium loads the page, runs its image check and dumps the
// DOM. Skipped (with a message) where /usr/bin/chromium is absent; scripts/setup.sh installs it.
#include <cstdio>
#include <cstdlib>

#include <gtest/gtest.h>

#include "d2gs/report/run_report.hpp"
#include "fake_run.hpp"
#include "test_paths.hpp"

namespace d2gs::report {
namespace {
namespace fs = std::filesystem;

constexpr const char* kChromium = "/usr/bin/chromium";

// The DOM after load, as Chromium serialises it.
std::string dump_dom(const fs::path& page, const fs::path& profile) {
  const std::string cmd = std::string(kChromium) +
                          " --headless --no-sandbox --disable-gpu --disable-quic --no-first-run"
                          " --disable-background-networking --disable-component-update --disable-sync"
                          " --user-data-dir='" + profile.string() + "' --dump-dom 'file://" + page.string() +
                          "' 2>/dev/null";
  std::string out;
  FILE* pipe = ::popen(cmd.c_str(), "r");
  if (!pipe) return out;
  char buffer[65536];
  std::size_t n;
  while ((n = std::fread(buffer, 1, sizeof buffer, pipe)) > 0) out.append(buffer, n);
  ::pclose(pipe);
  return out;
}

TEST(ReportChromium, RunReportLoadsWithEveryImageDecoded) {
  if (!fs::exists(kChromium)) GTEST_SKIP() << kChromium << " not installed (scripts/setup.sh installs chromium)";
  const auto dir = test::scratch_dir();
  test::make_fake_run(dir / "run");
  const fs::path page = write_run_report(dir / "run");
  const std::string dom = dump_dom(page, dir / "profile");
  ASSERT_NE(dom.find("</html>"), std::string::npos) << "chromium produced no DOM";
  for (const char* id : {"summary", "metrics", "curves", "views", "layers", "imr"})
    EXPECT_NE(dom.find(std::string("id=\"") + id + "\""), std::string::npos) << id;
  EXPECT_NE(dom.find("data-images-ok=\"6\""), std::string::npos) << "the page's image check did not pass";
  EXPECT_EQ(dom.find("id=\"load-error\""), std::string::npos);
}

TEST(ReportChromium, BrokenImageIsFlagged) {
  if (!fs::exists(kChromium)) GTEST_SKIP() << kChromium << " not installed (scripts/setup.sh installs chromium)";
  const auto dir = test::scratch_dir();
  HtmlPage page("broken");
  page.add_section("views", "Views", "<img src=\"data:image/png;base64,AAAAAAAA\" alt=\"bad one\">\n");
  write_file_atomic(dir / "broken.html", page.str());
  const std::string dom = dump_dom(dir / "broken.html", dir / "profile");
  EXPECT_NE(dom.find("id=\"load-error\""), std::string::npos) << dom.substr(0, 2000);
  EXPECT_NE(dom.find("bad one"), std::string::npos);
}

}  // namespace
}  // namespace d2gs::report
