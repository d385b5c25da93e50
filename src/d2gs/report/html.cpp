#include "d2gs/report/html.hpp"

#include <algorithm>
#include <array>
#include <cmath>

#include <fmt/format.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "d2gs/core/error.hpp"

namespace d2gs::report {

std::string html_escape(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  for (char ch : text) {
    switch (ch) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&#39;"; break;
      default: out += ch;
    }
  }
  return out;
}

std::string base64_encode(std::string_view bytes) {
  static constexpr char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  std::size_t i = 0;
  for (; i + 3 <= bytes.size(); i += 3) {
    const unsigned v = (static_cast<unsigned char>(bytes[i]) << 16) | (static_cast<unsigned char>(bytes[i + 1]) << 8) |
                       static_cast<unsigned char>(bytes[i + 2]);
    out += kAlphabet[(v >> 18) & 63];
    out += kAlphabet[(v >> 12) & 63];
    out += kAlphabet[(v >> 6) & 63];
    out += kAlphabet[v & 63];
  }
  const std::size_t rest = bytes.size() - i;
  if (rest > 0) {
    unsigned v = static_cast<unsigned char>(bytes[i]) << 16;
    if (rest == 2) v |= static_cast<unsigned char>(bytes[i + 1]) << 8;
    out += kAlphabet[(v >> 18) & 63];
    out += kAlphabet[(v >> 12) & 63];
    out += rest == 2 ? kAlphabet[(v >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

std::string image_data_uri(const Image& image, ImageEncoding encoding, int jpeg_quality) {
  if (image.empty() || image.width <= 0 || image.height <= 0) fail("report: cannot embed an empty image");
  const int c = image.channels;
  if (c != 1 && c != 3 && c != 4) fail("report: cannot embed an image with {} channels", c);
  // JPEG has no alpha: drop it.
  const int out_c = (encoding == ImageEncoding::Jpeg && c == 4) ? 3 : c;
  cv::Mat mat(image.height, image.width, CV_8UC(out_c));
  for (int y = 0; y < image.height; ++y) {
    auto* row = mat.ptr<unsigned char>(y);
    for (int x = 0; x < image.width; ++x)
      for (int k = 0; k < out_c; ++k) {
        // OpenCV stores BGR(A): swap the first and third channel.
        const int src = (out_c >= 3 && k < 3) ? 2 - k : k;
        const float v = std::clamp(image.at(x, y, src), 0.0f, 1.0f);
        row[x * out_c + k] = static_cast<unsigned char>(std::lround(v * 255.0f));
      }
  }
  std::vector<unsigned char> bytes;
  const bool png = encoding == ImageEncoding::Png;
  std::vector<int> params;
  if (!png) params = {cv::IMWRITE_JPEG_QUALITY, std::clamp(jpeg_quality, 1, 100)};
  if (!cv::imencode(png ? ".png" : ".jpg", mat, bytes, params)) fail("report: image encoding failed");
  return std::string(png ? "data:image/png;base64," : "data:image/jpeg;base64,") +
         base64_encode(std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
}

std::string img_tag(const Image& image, std::string_view alt, ImageEncoding encoding) {
  return fmt::format("<img src=\"{}\" alt=\"{}\" width=\"{}\" height=\"{}\">", image_data_uri(image, encoding),
                     html_escape(alt), image.width, image.height);
}

Image error_map(const Image& render, const Image& gt, float max_error) {
  if (render.width != gt.width || render.height != gt.height)
    fail("report: render ({}x{}) and ground truth ({}x{}) differ in size", render.width, render.height, gt.width,
         gt.height);
  const int cr = std::min(render.channels, 3), cg = std::min(gt.channels, 3);
  if (cr != cg) fail("report: render and ground truth differ in channels ({} vs {})", cr, cg);
  static constexpr std::array<std::array<float, 4>, 5> kStops = {{{0.00f, 0.00f, 0.00f, 0.02f},
                                                                  {0.25f, 0.26f, 0.04f, 0.42f},
                                                                  {0.50f, 0.70f, 0.18f, 0.40f},
                                                                  {0.75f, 0.98f, 0.53f, 0.10f},
                                                                  {1.00f, 0.99f, 0.98f, 0.70f}}};
  Image out(render.width, render.height, 3);
  const float scale = max_error > 0 ? 1.0f / max_error : 1.0f;
  for (int y = 0; y < render.height; ++y)
    for (int x = 0; x < render.width; ++x) {
      float e = 0;
      for (int k = 0; k < cr; ++k) e += std::fabs(render.at(x, y, k) - gt.at(x, y, k));
      const float t = std::clamp(e / static_cast<float>(cr) * scale, 0.0f, 1.0f);
      std::size_t s = 0;
      while (s + 2 < kStops.size() && t > kStops[s + 1][0]) ++s;
      const auto& a = kStops[s];
      const auto& b = kStops[s + 1];
      const float w = (t - a[0]) / (b[0] - a[0]);
      for (int k = 0; k < 3; ++k) out.at(x, y, k) = a[1 + k] + w * (b[1 + k] - a[1 + k]);
    }
  return out;
}

std::string html_table(const std::vector<std::string>& header, const std::vector<std::vector<std::string>>& rows,
                       std::size_t numeric_from) {
  std::string out = "<table>\n<thead><tr>";
  for (std::size_t i = 0; i < header.size(); ++i)
    out += fmt::format("<th{}>{}</th>", i >= numeric_from ? " class=\"num\"" : "", html_escape(header[i]));
  out += "</tr></thead>\n<tbody>\n";
  for (const auto& row : rows) {
    out += "<tr>";
    for (std::size_t i = 0; i < row.size(); ++i)
      out += fmt::format("<td{}>{}</td>", i >= numeric_from ? " class=\"num\"" : "", html_escape(row[i]));
    out += "</tr>\n";
  }
  return out + "</tbody>\n</table>\n";
}

HtmlPage::HtmlPage(std::string title, std::string subtitle) : title_(std::move(title)), subtitle_(std::move(subtitle)) {}

void HtmlPage::add_section(std::string id, std::string title, std::string body_html) {
  sections_.push_back({std::move(id), std::move(title), std::move(body_html)});
}

std::string HtmlPage::str() const {
  std::string out =
      "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
      "<meta name=\"generator\" content=\"d2gs\">\n<title>" +
      html_escape(title_) +
      "</title>\n<style>\n"
      "body{font-family:system-ui,-apple-system,'Segoe UI',Helvetica,Arial,sans-serif;margin:24px;color:#1d1d1f;"
      "background:#fff;max-width:1800px}\n"
      "h1{font-size:1.6em;margin:0 0 4px}h2{font-size:1.25em;border-bottom:1px solid #ccc;padding-bottom:4px;"
      "margin-top:32px}h3{font-size:1.05em;margin:18px 0 6px}\n"
      ".subtitle{color:#555;margin:0 0 12px}.note{color:#555;font-size:.9em}\n"
      "table{border-collapse:collapse;margin:8px 0;font-size:.92em}th,td{border:1px solid #d0d0d0;padding:3px 8px}"
      "th{background:#f2f2f2}td.num,th.num{text-align:right;font-variant-numeric:tabular-nums}\n"
      ".charts{display:flex;flex-wrap:wrap;gap:16px}.charts svg{border:1px solid #e0e0e0}\n"
      ".views{display:grid;gap:6px;align-items:start;max-width:1600px}"
      "figure{margin:0}figcaption{font-size:.85em;color:#333;text-align:center}"
      "figure img{width:100%;max-width:520px;height:auto;display:block}\n"
      ".load-error{color:#b00;font-weight:bold}\n"
      "</style>\n</head>\n<body>\n<header><h1>" +
      html_escape(title_) + "</h1>\n";
  if (!subtitle_.empty()) out += "<p class=\"subtitle\">" + html_escape(subtitle_) + "</p>\n";
  out += "<nav>";
  for (std::size_t i = 0; i < sections_.size(); ++i)
    out += fmt::format("{}<a href=\"#{}\">{}</a>", i ? " · " : "", html_escape(sections_[i].id),
                       html_escape(sections_[i].title));
  out += "</nav>\n</header>\n<main>\n";
  for (const auto& s : sections_)
    out += fmt::format("<section id=\"{}\">\n<h2>{}</h2>\n{}</section>\n", html_escape(s.id), html_escape(s.title),
                       s.body);
  // A check a headless browser runs: every embedded image must decode. Broken ones are listed in a
  // "load-error" element; a page that loads cleanly gets data-images-ok on <body>.
  out +=
      "</main>\n<script>\nwindow.addEventListener('load',function(){var bad=[];"
      "var imgs=document.images;for(var i=0;i<imgs.length;i++){if(!imgs[i].complete||imgs[i].naturalWidth===0)"
      "bad.push(imgs[i].alt||('image '+i));}"
      "if(bad.length){var p=document.createElement('p');p.className='load-error';p.id='load-error';"
      "p.textContent='images that failed to load: '+bad.join(', ');document.body.insertBefore(p,"
      "document.body.firstChild);}else{document.body.setAttribute('data-images-ok',String(imgs.length));}});\n"
      "</script>\n</body>\n</html>\n";
  return out;
}

}  // namespace d2gs::report
