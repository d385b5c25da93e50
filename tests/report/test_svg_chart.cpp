// Inline SVG charts: ticks, points, escaping, empty data.
#include <gtest/gtest.h>

#include "d2gs/report/svg_chart.hpp"
#include "fake_run.hpp"
#include "test_paths.hpp"

namespace d2gs::report {
namespace {

using test::count_occurrences;

TEST(SvgChart, NiceTicks) {
  EXPECT_EQ(nice_ticks(0, 10, 5), (std::vector<double>{0, 2, 4, 6, 8, 10}));
  EXPECT_EQ(nice_ticks(0, 1000, 4), (std::vector<double>{0, 250, 500, 750, 1000}));
  const auto t = nice_ticks(12.02, 12.09, 4);
  ASSERT_GE(t.size(), 3u);
  for (double v : t) {
    EXPECT_GE(v, 12.02 - 1e-9);
    EXPECT_LE(v, 12.09 + 1e-9);
  }
  EXPECT_EQ(nice_ticks(3, 3), (std::vector<double>{3}));
}

TEST(SvgChart, LineChartDrawsEveryFinitePointAndEscapesNames) {
  LineChart c{"loss <train>", "iteration", "loss", {}, false};
  c.series.push_back({"3dgs & co", {1, 2, 3, 4}, {0.5, 0.4, std::nan(""), 0.2}, false});
  c.series.push_back({"d2gs", {1, 4}, {0.6, 0.1}, true});
  const std::string svg = svg_line_chart(c);
  EXPECT_EQ(test::check_balanced(svg), "") << svg;
  EXPECT_EQ(count_occurrences(svg, "<polyline"), 2u);
  EXPECT_EQ(count_occurrences(svg, "<circle"), 2u);  // markers of the second series only
  const std::size_t p = svg.find("points=\"");
  const std::string pts = svg.substr(p + 8, svg.find('"', p + 8) - p - 8);
  EXPECT_EQ(count_occurrences(pts, ","), 3u);  // the NaN point is skipped
  EXPECT_NE(svg.find("3dgs &amp; co"), std::string::npos);
  EXPECT_NE(svg.find("loss &lt;train&gt;"), std::string::npos);
  EXPECT_EQ(svg.find("no data"), std::string::npos);
}

TEST(SvgChart, LogAxisSkipsNonPositiveValuesAndEmptyChartSaysSo) {
  LineChart c{"loss", "it", "loss", {}, true};
  c.series.push_back({"", {1, 2, 3}, {0.0, 0.3, 0.25}, false});
  const std::string svg = svg_line_chart(c);
  const std::size_t p = svg.find("points=\"");
  EXPECT_EQ(count_occurrences(svg.substr(p, svg.find("\"", p + 8) - p), ","), 2u);
  EXPECT_NE(svg.find(">0.3<"), std::string::npos) << svg;  // linear ticks within one decade
  LineChart empty{"nothing", "x", "y", {}, false};
  empty.series.push_back({"a", {}, {}, false});
  EXPECT_NE(svg_line_chart(empty).find("no data"), std::string::npos);
}

TEST(SvgChart, BarChartHasOneBarPerSeriesAndCategory) {
  BarChart b{"layers", "Gaussians", {"near", "middle", "far"}, {}};
  b.series.push_back({"3dgs", {}, {30, 20, 10}, false});
  b.series.push_back({"d2gs", {}, {20, 20, 20}, false});
  const std::string svg = svg_bar_chart(b);
  EXPECT_EQ(test::check_balanced(svg), "") << svg;
  EXPECT_EQ(count_occurrences(svg, "<title>"), 6u);
  EXPECT_NE(svg.find("<title>3dgs / near: 30</title>"), std::string::npos);
}

}  // namespace
}  // namespace d2gs::report
