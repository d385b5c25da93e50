#include "d2gs/core/error.hpp"

#include <algorithm>

namespace d2gs {

namespace {

// Length of the valid UTF-8 encoding of one printable character at the start of `s` (2 to 4 bytes), or
// 0: overlong forms, surrogates, values beyond U+10FFFF and the C1 controls (U+0080..U+009F) are not.
std::size_t utf8_char_length(std::string_view s) {
  const auto byte = [&](std::size_t i) { return static_cast<unsigned char>(s[i]); };
  const unsigned char b0 = byte(0);
  std::size_t n = 0;
  unsigned char lo = 0x80, hi = 0xbf;  // range of the second byte
  if (b0 >= 0xc2 && b0 <= 0xdf) n = 2;
  else if (b0 >= 0xe0 && b0 <= 0xef) n = 3;
  else if (b0 >= 0xf0 && b0 <= 0xf4) n = 4;
  else return 0;
  if (b0 == 0xc2) lo = 0xa0;  // U+0080..U+009F: C1 controls
  if (b0 == 0xe0) lo = 0xa0;  // overlong
  if (b0 == 0xed) hi = 0x9f;  // surrogates
  if (b0 == 0xf0) lo = 0x90;  // overlong
  if (b0 == 0xf4) hi = 0x8f;  // beyond U+10FFFF
  if (s.size() < n || byte(1) < lo || byte(1) > hi) return 0;
  for (std::size_t i = 2; i < n; ++i)
    if (byte(i) < 0x80 || byte(i) > 0xbf) return 0;
  return n;
}

}  // namespace

std::string printable(std::string_view text, std::size_t max_bytes) {
  const std::string_view shown = text.substr(0, std::min(text.size(), max_bytes));
  std::string out;
  out.reserve(shown.size());
  for (std::size_t i = 0; i < shown.size();) {
    const auto c = static_cast<unsigned char>(shown[i]);
    if (c >= 0x20 && c < 0x7f) {
      out += shown[i++];
    } else if (const std::size_t n = utf8_char_length(shown.substr(i)); n > 0) {
      out.append(shown.substr(i, n));
      i += n;
    } else {
      out += fmt::format("\\x{:02x}", c);
      ++i;
    }
  }
  if (shown.size() < text.size()) out += "...";
  return out;
}

}  // namespace d2gs
