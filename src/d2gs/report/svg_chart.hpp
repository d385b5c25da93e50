#pragma once
// Inline SVG charts for the HTML reports: line charts (training curves) and grouped bar charts (Gaussian
// counts per depth layer). Pure strings, no script; names are escaped.
#include <string>
#include <vector>

namespace d2gs::report {

struct Series {
  std::string name;
  std::vector<double> x, y;  // same length; non-finite points are skipped
  bool markers = false;      // draw a dot at every point (sparse series such as test PSNR)
};

struct LineChart {
  std::string title, x_label, y_label;
  std::vector<Series> series;
  bool log_y = false;  // logarithmic y axis (values ≤ 0 skipped)
  int width = 600, height = 300;
};

// <svg>…</svg>. A chart without any drawable point says so inside the frame.
std::string svg_line_chart(const LineChart& chart);

struct BarChart {
  std::string title, y_label;
  std::vector<std::string> categories;  // groups along x (e.g. near, middle, far)
  std::vector<Series> series;           // one bar per series in each group; y[k] is category k's value
  int width = 600, height = 300;
};

std::string svg_bar_chart(const BarChart& chart);

// Colour of series k (a fixed palette, cycled).
const char* series_colour(std::size_t k);
// "Nice" axis ticks covering [lo, hi] (about `count` of them).
std::vector<double> nice_ticks(double lo, double hi, int count = 5);

}  // namespace d2gs::report
