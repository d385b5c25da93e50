#include "d2gs/report/svg_chart.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <fmt/format.h>

#include "d2gs/report/html.hpp"

namespace d2gs::report {
namespace {

constexpr double kLeft = 62, kRight = 16, kTop = 30, kBottom = 44, kLegend = 140;

std::string tick_label(double v) {
  const double a = std::fabs(v);
  if (a != 0 && (a >= 1e5 || a < 1e-3)) return fmt::format("{:.2g}", v);
  if (a >= 100 || v == std::round(v)) return fmt::format("{:.0f}", v);
  if (a >= 1) return fmt::format("{:.2f}", v);
  return fmt::format("{:.3g}", v);
}

std::string frame(int width, int height, const std::string& title, const std::string& y_label,
                  const std::string& x_label) {
  std::string s = fmt::format(
      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{0}\" height=\"{1}\" viewBox=\"0 0 {0} {1}\" "
      "font-family=\"sans-serif\" font-size=\"11\" role=\"img\" aria-label=\"{2}\">\n"
      "<rect x=\"0\" y=\"0\" width=\"{0}\" height=\"{1}\" fill=\"#fff\"/>\n"
      "<text x=\"{3}\" y=\"18\" text-anchor=\"middle\" font-size=\"13\" font-weight=\"bold\">{2}</text>\n",
      width, height, html_escape(title), width / 2);
  if (!y_label.empty())
    s += fmt::format("<text x=\"14\" y=\"{0}\" text-anchor=\"middle\" transform=\"rotate(-90 14 {0})\">{1}</text>\n",
                     (kTop + height - kBottom) / 2, html_escape(y_label));
  if (!x_label.empty())
    s += fmt::format("<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">{}</text>\n", (kLeft + width - kRight - kLegend) / 2,
                     height - 6, html_escape(x_label));
  return s;
}

std::string legend(const std::vector<Series>& series, double x0, double y0) {
  std::string s;
  for (std::size_t k = 0; k < series.size(); ++k) {
    const double y = y0 + 14.0 * static_cast<double>(k);
    s += fmt::format("<rect x=\"{:.1f}\" y=\"{:.1f}\" width=\"12\" height=\"3\" fill=\"{}\"/>"
                     "<text x=\"{:.1f}\" y=\"{:.1f}\">{}</text>\n",
                     x0, y - 4, series_colour(k), x0 + 16, y, html_escape(series[k].name));
  }
  return s;
}

}  // namespace

const char* series_colour(std::size_t k) {
  static constexpr const char* kPalette[] = {"#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd",
                                             "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf"};
  return kPalette[k % (sizeof kPalette / sizeof kPalette[0])];
}

std::vector<double> nice_ticks(double lo, double hi, int count) {
  if (!(std::isfinite(lo) && std::isfinite(hi))) return {};
  if (hi < lo) std::swap(lo, hi);
  if (hi == lo) return {lo};
  const double raw = (hi - lo) / std::max(1, count);
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  double step = mag;
  for (double m : {1.0, 2.0, 2.5, 5.0, 10.0})
    if (m * mag >= raw) {
      step = m * mag;
      break;
    }
  std::vector<double> ticks;
  for (double v = std::ceil(lo / step - 1e-9) * step; v <= hi + step * 1e-9; v += step)
    ticks.push_back(std::fabs(v) < step * 1e-9 ? 0.0 : v);
  return ticks;
}

std::string svg_line_chart(const LineChart& chart) {
  const int w = chart.width, h = chart.height;
  std::string s = frame(w, h, chart.title, chart.y_label, chart.x_label);
  const auto ty = [&](double v) { return chart.log_y ? std::log10(v) : v; };
  double x0 = std::numeric_limits<double>::infinity(), x1 = -x0, y0 = x0, y1 = -x0;
  for (const auto& se : chart.series)
    for (std::size_t i = 0; i < std::min(se.x.size(), se.y.size()); ++i) {
      if (!std::isfinite(se.x[i]) || !std::isfinite(se.y[i]) || (chart.log_y && se.y[i] <= 0)) continue;
      x0 = std::min(x0, se.x[i]);
      x1 = std::max(x1, se.x[i]);
      y0 = std::min(y0, ty(se.y[i]));
      y1 = std::max(y1, ty(se.y[i]));
    }
  const bool has_legend = chart.series.size() > 1 || (chart.series.size() == 1 && !chart.series[0].name.empty());
  const double pl = kLeft, pr = w - kRight - (has_legend ? kLegend : 0.0), pt = kTop, pb = h - kBottom;
  s += fmt::format("<rect x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" fill=\"none\" stroke=\"#999\"/>\n", pl, pt,
                   pr - pl, pb - pt);
  if (!(x0 <= x1)) {
    s += fmt::format("<text x=\"{}\" y=\"{}\" text-anchor=\"middle\" fill=\"#777\">no data</text>\n</svg>\n",
                     (pl + pr) / 2, (pt + pb) / 2);
    return s;
  }
  if (x0 == x1) {
    x0 -= 0.5;
    x1 += 0.5;
  }
  if (y0 == y1) {
    const double pad = std::max(std::fabs(y0) * 0.05, 1e-6);
    y0 -= pad;
    y1 += pad;
  } else {
    const double pad = (y1 - y0) * 0.05;
    y0 -= pad;
    y1 += pad;
  }
  const auto px = [&](double x) { return pl + (x - x0) / (x1 - x0) * (pr - pl); };
  const auto py = [&](double y) { return pb - (ty(y) - y0) / (y1 - y0) * (pb - pt); };
  // axes and ticks
  for (double t : nice_ticks(x0, x1, 5))
    s += fmt::format("<line x1=\"{0:.1f}\" y1=\"{1}\" x2=\"{0:.1f}\" y2=\"{2}\" stroke=\"#eee\"/>"
                     "<text x=\"{0:.1f}\" y=\"{3}\" text-anchor=\"middle\">{4}</text>\n",
                     px(t), pt, pb, pb + 14, tick_label(t));
  if (chart.log_y) {
    // Powers of ten when the range spans two or more; else linear ticks placed on the log axis.
    std::vector<double> values;
    for (double e = std::ceil(y0); e <= y1; e += 1.0) values.push_back(std::pow(10.0, e));
    if (values.size() < 2) {
      values.clear();
      for (double t : nice_ticks(std::pow(10.0, y0), std::pow(10.0, y1), 4))
        if (t > 0) values.push_back(t);
    }
    for (double t : values) {
      const double yy = pb - (std::log10(t) - y0) / (y1 - y0) * (pb - pt);
      s += fmt::format("<line x1=\"{0}\" y1=\"{1:.1f}\" x2=\"{2}\" y2=\"{1:.1f}\" stroke=\"#eee\"/>"
                       "<text x=\"{3}\" y=\"{4:.1f}\" text-anchor=\"end\">{5}</text>\n",
                       pl, yy, pr, pl - 4, yy + 4, tick_label(t));
    }
  } else {
    for (double t : nice_ticks(y0, y1, 5)) {
      const double yy = pb - (t - y0) / (y1 - y0) * (pb - pt);
      s += fmt::format("<line x1=\"{0}\" y1=\"{1:.1f}\" x2=\"{2}\" y2=\"{1:.1f}\" stroke=\"#eee\"/>"
                       "<text x=\"{3}\" y=\"{4:.1f}\" text-anchor=\"end\">{5}</text>\n",
                       pl, yy, pr, pl - 4, yy + 4, tick_label(t));
    }
  }
  for (std::size_t k = 0; k < chart.series.size(); ++k) {
    const auto& se = chart.series[k];
    std::string points;
    std::string dots;
    for (std::size_t i = 0; i < std::min(se.x.size(), se.y.size()); ++i) {
      if (!std::isfinite(se.x[i]) || !std::isfinite(se.y[i]) || (chart.log_y && se.y[i] <= 0)) continue;
      points += fmt::format("{:.1f},{:.1f} ", px(se.x[i]), py(se.y[i]));
      if (se.markers)
        dots += fmt::format("<circle cx=\"{:.1f}\" cy=\"{:.1f}\" r=\"3\" fill=\"{}\"/>", px(se.x[i]), py(se.y[i]),
                            series_colour(k));
    }
    if (!points.empty()) points.pop_back();
    s += fmt::format("<polyline fill=\"none\" stroke=\"{}\" stroke-width=\"1.5\" points=\"{}\"/>{}\n",
                     series_colour(k), points, dots);
  }
  if (has_legend) s += legend(chart.series, pr + 10, pt + 10);
  return s + "</svg>\n";
}

std::string svg_bar_chart(const BarChart& chart) {
  const int w = chart.width, h = chart.height;
  std::string s = frame(w, h, chart.title, chart.y_label, {});
  const double pl = kLeft, pr = w - kRight - (chart.series.empty() ? 0.0 : kLegend), pt = kTop, pb = h - kBottom;
  double y1 = 0;
  for (const auto& se : chart.series)
    for (double v : se.y)
      if (std::isfinite(v)) y1 = std::max(y1, v);
  if (y1 <= 0) y1 = 1;
  const auto ticks = nice_ticks(0, y1 * 1.05, 5);
  const double top = std::max(y1 * 1.05, ticks.empty() ? y1 : ticks.back());
  const auto py = [&](double v) { return pb - v / top * (pb - pt); };
  for (double t : ticks)
    s += fmt::format("<line x1=\"{0}\" y1=\"{1:.1f}\" x2=\"{2}\" y2=\"{1:.1f}\" stroke=\"#eee\"/>"
                     "<text x=\"{3}\" y=\"{4:.1f}\" text-anchor=\"end\">{5}</text>\n",
                     pl, py(t), pr, pl - 4, py(t) + 4, tick_label(t));
  s += fmt::format("<line x1=\"{0}\" y1=\"{1}\" x2=\"{2}\" y2=\"{1}\" stroke=\"#666\"/>\n", pl, pb, pr);
  const std::size_t groups = std::max<std::size_t>(1, chart.categories.size());
  const std::size_t bars = std::max<std::size_t>(1, chart.series.size());
  const double group_w = (pr - pl) / static_cast<double>(groups);
  const double bar_w = group_w * 0.8 / static_cast<double>(bars);
  for (std::size_t g = 0; g < chart.categories.size(); ++g) {
    const double gx = pl + group_w * static_cast<double>(g);
    s += fmt::format("<text x=\"{:.1f}\" y=\"{}\" text-anchor=\"middle\">{}</text>\n", gx + group_w / 2, pb + 14,
                     html_escape(chart.categories[g]));
    for (std::size_t k = 0; k < chart.series.size(); ++k) {
      const auto& se = chart.series[k];
      if (g >= se.y.size() || !std::isfinite(se.y[g])) continue;
      const double x = gx + group_w * 0.1 + bar_w * static_cast<double>(k);
      s += fmt::format("<rect x=\"{:.1f}\" y=\"{:.1f}\" width=\"{:.1f}\" height=\"{:.1f}\" fill=\"{}\">"
                       "<title>{}: {}</title></rect>\n",
                       x, py(se.y[g]), bar_w * 0.92, pb - py(se.y[g]), series_colour(k),
                       html_escape(se.name + " / " + chart.categories[g]), tick_label(se.y[g]));
    }
  }
  if (!chart.series.empty()) s += legend(chart.series, pr + 10, pt + 10);
  return s + "</svg>\n";
}

}  // namespace d2gs::report
