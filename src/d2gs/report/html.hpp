#pragma once
// Building blocks of the self-contained HTML reports: escaping, base64, images embedded as data URIs,
// error maps, and a page made of titled sections. Nothing refers to an outside resource: no external
// script, font, style sheet or image, so one file carries the whole report.
#include <string>
#include <string_view>
#include <vector>

#include "d2gs/core/image.hpp"

namespace d2gs::report {

// &, <, >, " and ' replaced by entities (safe in text and in quoted attribute values).
std::string html_escape(std::string_view text);
// RFC 4648 base64 with padding.
std::string base64_encode(std::string_view bytes);

enum class ImageEncoding { Png, Jpeg };
// The image (float RGB/RGBA/grey in [0, 1]) encoded in memory and wrapped as "data:image/...;base64,...".
std::string image_data_uri(const Image& image, ImageEncoding encoding = ImageEncoding::Png, int jpeg_quality = 90);
// <img> with an embedded image, alt text escaped.
std::string img_tag(const Image& image, std::string_view alt, ImageEncoding encoding = ImageEncoding::Png);

// Per-pixel error |render − gt| (mean over the colour channels) divided by `max_error` and mapped to a
// dark-to-bright colour scale (black → purple → orange → pale yellow). Sizes must match.
Image error_map(const Image& render, const Image& gt, float max_error = 0.25f);

// A table: header cells and rows of cells, all escaped. `numeric_from` right-aligns columns from there.
std::string html_table(const std::vector<std::string>& header, const std::vector<std::vector<std::string>>& rows,
                       std::size_t numeric_from = 1);

// A page of sections. Each section becomes <section id="ID"><h2>TITLE</h2>BODY</section>; BODY is raw
// HTML (callers escape what they put in). The page ends with a small inline script that marks the page
// when an embedded image fails to decode (a "load-error" element), so headless checks can see it.
class HtmlPage {
public:
  explicit HtmlPage(std::string title, std::string subtitle = {});
  void add_section(std::string id, std::string title, std::string body_html);
  std::string str() const;

private:
  struct Section {
    std::string id, title, body;
  };
  std::string title_, subtitle_;
  std::vector<Section> sections_;
};

}  // namespace d2gs::report
