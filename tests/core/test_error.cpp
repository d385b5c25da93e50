// Messages that quote file content (core/error.hpp: printable).
#include "d2gs/core/error.hpp"

#include <gtest/gtest.h>

#include <string>

namespace d2gs {
namespace {

using namespace std::string_literals;

TEST(Printable, EscapesBytesThatAreNotPrintableText) {
  EXPECT_EQ(printable("camera_1 PINHOLE"), "camera_1 PINHOLE");
  EXPECT_EQ(printable("\0\0\0\xff\xfe"s), "\\x00\\x00\\x00\\xff\\xfe");
  EXPECT_EQ(printable("a\tb\nc\r\x1b[31m\x7f"), "a\\x09b\\x0ac\\x0d\\x1b[31m\\x7f");
  // Valid UTF-8 characters are text; broken, overlong or surrogate sequences and C1 controls are not.
  EXPECT_EQ(printable("caf\xc3\xa9 \xe2\x82\xac \xf0\x9f\x98\x80"), "caf\xc3\xa9 \xe2\x82\xac \xf0\x9f\x98\x80");
  EXPECT_EQ(printable("\xc3("), "\\xc3(");
  EXPECT_EQ(printable("\xc0\xaf"), "\\xc0\\xaf");
  EXPECT_EQ(printable("\xed\xa0\x80"), "\\xed\\xa0\\x80");
  EXPECT_EQ(printable("\xc2\x85"), "\\xc2\\x85");
  EXPECT_EQ(printable("\xf4\x90\x80\x80"), "\\xf4\\x90\\x80\\x80");
}

TEST(Printable, CutsLongTextAndNeverHoldsANulOrALineEnd) {
  EXPECT_EQ(printable(std::string(100, 'x')), std::string(60, 'x') + "...");
  EXPECT_EQ(printable(std::string(60, 'x')), std::string(60, 'x'));
  EXPECT_EQ(printable("abcdef", 3), "abc...");
  EXPECT_EQ(printable(""), "");
  std::string all;
  for (int c = 0; c < 256; ++c) all += static_cast<char>(c);
  const std::string shown = printable(all, all.size());
  EXPECT_EQ(shown.find('\0'), std::string::npos);
  EXPECT_EQ(shown.find('\n'), std::string::npos);
  for (char c : shown) EXPECT_TRUE(c >= 0x20 && c < 0x7f) << static_cast<int>(static_cast<unsigned char>(c));
}

}  // namespace
}  // namespace d2gs
