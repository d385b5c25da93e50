#include "d2gs/core/image.hpp"

#include <csetjmp>
#include <cstdio>
#include <cstring>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <jpeglib.h>
// jpeglib.h first: jerror.h needs its types.
#include <jerror.h>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/checksum.hpp"
#include "d2gs/core/error.hpp"

namespace d2gs {
namespace fs = std::filesystem;

namespace {

Image from_mat(const cv::Mat& decoded, const fs::path& path) {
  cv::Mat m = decoded;
  double scale = 1.0;
  switch (m.depth()) {
    case CV_8U: scale = 1.0 / 255.0; break;
    case CV_16U: scale = 1.0 / 65535.0; break;
    case CV_32F: scale = 1.0; break;
    default: fail_file(path, "unsupported pixel depth");
  }
  const int c = m.channels();
  if (c == 3) cv::cvtColor(m, m, cv::COLOR_BGR2RGB);
  else if (c == 4) cv::cvtColor(m, m, cv::COLOR_BGRA2RGBA);
  else if (c != 1) fail_file(path, "unsupported channel count {}", c);
  cv::Mat f;
  m.convertTo(f, CV_32F, scale);
  Image out(f.cols, f.rows, c);
  for (int y = 0; y < f.rows; ++y) {
    const float* row = f.ptr<float>(y);
    std::copy(row, row + static_cast<std::size_t>(f.cols) * c, out.pixels.begin() + static_cast<std::ptrdiff_t>(y) * f.cols * c);
  }
  return out;
}

cv::Mat to_mat(const Image& image) {
  const int type = CV_MAKETYPE(CV_32F, image.channels);
  return cv::Mat(image.height, image.width, type, const_cast<float*>(image.pixels.data()));
}

std::uint32_t be32(const unsigned char* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) | p[3];
}

bool is_png(std::string_view bytes) {
  static constexpr char magic[8] = {'\x89', 'P', 'N', 'G', '\r', '\n', '\x1a', '\n'};
  return bytes.starts_with(std::string_view(magic, sizeof magic));
}

// A PNG's chunk structure (length, type, data, CRC-32 of type and data), walked to IEND before libpng sees
// the file: libpng reports a truncated or damaged chunk on stderr by itself, then OpenCV says only that it
// could not decode. "" when the structure is whole; the deflate stream inside IDAT is libpng's to check.
std::string png_problem(std::string_view bytes) {
  const auto* p = reinterpret_cast<const unsigned char*>(bytes.data());
  std::size_t at = 8;
  bool first = true;
  while (true) {
    if (bytes.size() - at < 12)
      return at == bytes.size() ? "truncated: no IEND chunk" : "truncated: the file ends inside a chunk header";
    const std::uint32_t length = be32(p + at);
    const std::string type(bytes.substr(at + 4, 4));
    if (length > 0x7FFFFFFFu) return "chunk " + type + " has an impossible length";
    if (first && type != "IHDR") return "the first chunk is not IHDR";
    first = false;
    if (bytes.size() - at - 12 < length) return "truncated: the file ends inside chunk " + type;
    const std::uint32_t stored = be32(p + at + 8 + length);
    if (crc32(bytes.substr(at + 4, 4 + length)) != stored) return "chunk " + type + " is damaged (CRC mismatch)";
    at += 12 + length;
    if (type == "IEND") return "";
  }
}

bool is_jpeg(std::string_view bytes) {
  return bytes.size() >= 3 && static_cast<unsigned char>(bytes[0]) == 0xFF &&
         static_cast<unsigned char>(bytes[1]) == 0xD8 && static_cast<unsigned char>(bytes[2]) == 0xFF;
}

// libjpeg recovers from a truncated or damaged stream with a warning (grey or repeated blocks in the
// image) that OpenCV does not pass on. The stream is decoded once more here, at 1/8 scale (every
// entropy-coded bit is still read, little else is done), and any warning or error is fatal.
struct JpegErrors {
  jpeg_error_mgr mgr;
  std::jmp_buf jump;
  std::string first_message;
};

void jpeg_on_error(j_common_ptr info) {
  auto* e = reinterpret_cast<JpegErrors*>(info->err);
  if (e->first_message.empty()) {
    char text[JMSG_LENGTH_MAX] = {};
    (*info->err->format_message)(info, text);
    e->first_message = text;
  }
  std::longjmp(e->jump, 1);
}

void jpeg_on_message(j_common_ptr info, int level) {
  if (level >= 0) return;  // trace messages
  // Warnings that leave every pixel intact (stray bytes between segments, an unknown JFIF revision or
  // Adobe transform) pass; the others mean missing or damaged image data.
  const int code = info->err->msg_code;
  if (code == JWRN_EXTRANEOUS_DATA || code == JWRN_JFIF_MAJOR || code == JWRN_ADOBE_XFORM) return;
  jpeg_on_error(info);
}

// Reads the whole stream: header, every scan, the end marker. libjpeg's errors leave through longjmp.
void jpeg_read_everything(jpeg_decompress_struct& info, std::string_view bytes) {
  jpeg_create_decompress(&info);
  jpeg_mem_src(&info, reinterpret_cast<const unsigned char*>(bytes.data()), static_cast<unsigned long>(bytes.size()));
  jpeg_read_header(&info, TRUE);
  info.scale_num = 1;
  info.scale_denom = 8;
  info.dct_method = JDCT_IFAST;
  info.do_fancy_upsampling = FALSE;
  jpeg_start_decompress(&info);
  JSAMPARRAY row = (*info.mem->alloc_sarray)(reinterpret_cast<j_common_ptr>(&info), JPOOL_IMAGE,
                                             info.output_width * static_cast<JDIMENSION>(info.output_components), 1);
  while (info.output_scanline < info.output_height) jpeg_read_scanlines(&info, row, 1);
  jpeg_finish_decompress(&info);
}

// Empty when the stream decodes cleanly, else libjpeg's first complaint. Only these two objects, whose
// addresses libjpeg holds, live across setjmp; no C++ object with a destructor is skipped by longjmp.
std::string jpeg_problem(std::string_view bytes) {
  jpeg_decompress_struct info{};
  JpegErrors errors{};
  info.err = jpeg_std_error(&errors.mgr);
  errors.mgr.error_exit = jpeg_on_error;
  errors.mgr.emit_message = jpeg_on_message;
  if (setjmp(errors.jump)) {
    jpeg_destroy_decompress(&info);
    return errors.first_message.empty() ? std::string("undecodable JPEG data") : errors.first_message;
  }
  jpeg_read_everything(info, bytes);
  jpeg_destroy_decompress(&info);
  return {};
}

// The frame size from libjpeg's own header reader, which skips stray bytes and fill the way the decoder
// does (a hand-written marker walk disagreed with it on damaged streams). Reads only up to the first
// scan, from the source `set_source` installs. Empty when the header is read, else libjpeg's complaint;
// only plain objects live across setjmp.
template <class SetSource>
std::string jpeg_frame_size(const SetSource& set_source, ImageSize& size) {
  jpeg_decompress_struct info{};
  JpegErrors errors{};
  info.err = jpeg_std_error(&errors.mgr);
  errors.mgr.error_exit = jpeg_on_error;
  errors.mgr.emit_message = [](j_common_ptr, int) {};  // the decoder judges the data; only the size is read here
  if (setjmp(errors.jump)) {
    jpeg_destroy_decompress(&info);
    return errors.first_message.empty() ? std::string("undecodable JPEG header") : errors.first_message;
  }
  jpeg_create_decompress(&info);
  set_source(info);
  jpeg_read_header(&info, TRUE);
  const JDIMENSION w = info.image_width, h = info.image_height;
  jpeg_destroy_decompress(&info);
  if (w == 0 || h == 0 || w > INT32_MAX || h > INT32_MAX) return "zero or huge frame size";
  size = {static_cast<int>(w), static_cast<int>(h)};
  return {};
}

std::string jpeg_header_size(const fs::path& path, ImageSize& size) {
  std::FILE* file = std::fopen(path.c_str(), "rb");
  if (file == nullptr) return "cannot open the file";
  const std::string problem = jpeg_frame_size([&](jpeg_decompress_struct& info) { jpeg_stdio_src(&info, file); }, size);
  std::fclose(file);
  return problem;
}

// The declared frame of PNG or JPEG bytes, when their header can be read (else the decoder's checks speak).
std::optional<ImageSize> declared_size(std::string_view bytes, bool jpeg) {
  const auto* p = reinterpret_cast<const unsigned char*>(bytes.data());
  if (!jpeg) {
    if (bytes.size() < 24 || !std::equal(p + 12, p + 16, reinterpret_cast<const unsigned char*>("IHDR")))
      return std::nullopt;
    const auto w = be32(p + 16), h = be32(p + 20);
    if (w == 0 || h == 0 || w > INT32_MAX || h > INT32_MAX) return std::nullopt;
    return ImageSize{static_cast<int>(w), static_cast<int>(h)};
  }
  ImageSize size;
  const std::string problem = jpeg_frame_size(
      [&](jpeg_decompress_struct& info) { jpeg_mem_src(&info, p, static_cast<unsigned long>(bytes.size())); }, size);
  if (!problem.empty()) return std::nullopt;
  return size;
}

void check_frame_size(ImageSize size, const fs::path& source) {
  if (static_cast<std::int64_t>(size.width) * size.height > kMaxImagePixels)
    fail_file(source, "image is {}x{}: more than the {} pixels d2gs decodes", size.width, size.height, kMaxImagePixels);
}

ImageReadObserver& image_read_observer() {
  static ImageReadObserver observer;
  return observer;
}

}  // namespace

void set_image_read_observer(ImageReadObserver observer) { image_read_observer() = std::move(observer); }

Image read_image(const fs::path& path) {
  if (image_read_observer()) image_read_observer()(path);
  std::error_code ec;
  if (!fs::exists(path, ec)) fail_file(path, "image not found");
  return decode_image(read_file(path), path);
}

Image decode_image(std::string_view bytes, const fs::path& source) {
  if (bytes.empty()) fail_file(source, "cannot decode image (empty file)");
  // Only PNG and JPEG reach OpenCV: imdecode picks a decoder by the bytes alone, and some of the others it
  // is built with abort the process on a malformed file instead of failing (GDCM's DICOM reader asserts on
  // a file with "DICM" at byte 128: fuzz/corpus/fuzz_image/dicom-magic-at-128.bin).
  const bool jpeg = is_jpeg(bytes);
  if (!jpeg && !is_png(bytes)) fail_file(source, "not a PNG or JPEG file (the image formats d2gs reads)");
  if (const auto size = declared_size(bytes, jpeg)) check_frame_size(*size, source);
  if (jpeg) {
    const std::string problem = jpeg_problem(bytes);
    if (!problem.empty()) fail_file(source, "corrupt or truncated JPEG ({})", problem);
  } else if (const std::string problem = png_problem(bytes); !problem.empty()) {
    fail_file(source, "corrupt or truncated PNG ({})", problem);
  }
  cv::Mat m;
  try {
    const cv::Mat buffer(1, static_cast<int>(std::min<std::size_t>(bytes.size(), INT32_MAX)), CV_8U,
                         const_cast<char*>(bytes.data()));
    m = cv::imdecode(buffer, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    fail_file(source, "cannot decode image ({})", e.err);
  }
  if (m.empty()) fail_file(source, "cannot decode image (corrupt or unsupported format)");
  return from_mat(m, source);
}

ImageSize read_image_size(const fs::path& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) fail_file(path, "image not found");
  require_regular_file(path);  // a named pipe would block the open
  std::ifstream in(path, std::ios::binary);
  if (!in) fail_file(path, "cannot open: {}", std::strerror(errno));
  ImageSize size{};
  unsigned char head[32] = {};
  in.read(reinterpret_cast<char*>(head), sizeof head);
  const auto got = in.gcount();
  if (got >= 24 && is_png(std::string_view(reinterpret_cast<const char*>(head), static_cast<std::size_t>(got)))) {
    if (!std::equal(head + 12, head + 16, reinterpret_cast<const unsigned char*>("IHDR")))
      fail_file(path, "corrupt PNG header");
    const auto w = be32(head + 16), h = be32(head + 20);
    if (w == 0 || h == 0 || w > 1u << 16 || h > 1u << 16) fail_file(path, "corrupt PNG header (size {}x{})", w, h);
    size = {static_cast<int>(w), static_cast<int>(h)};
    check_frame_size(size, path);
    return size;
  }
  if (got >= 4 && head[0] == 0xFF && head[1] == 0xD8) {
    const std::string problem = jpeg_header_size(path, size);
    if (!problem.empty()) fail_file(path, "corrupt JPEG header ({})", problem);
    check_frame_size(size, path);
    return size;
  }
  const Image decoded = read_image(path);
  return {decoded.width, decoded.height};
}

Image resize_area(const Image& image, int width, int height) {
  if (width <= 0 || height <= 0) fail("resize_area: invalid target size {}x{}", width, height);
  cv::Mat dst;
  cv::resize(to_mat(image), dst, cv::Size(width, height), 0, 0, cv::INTER_AREA);
  Image out(width, height, image.channels);
  for (int y = 0; y < height; ++y) {
    const float* row = dst.ptr<float>(y);
    std::copy(row, row + static_cast<std::size_t>(width) * image.channels,
              out.pixels.begin() + static_cast<std::ptrdiff_t>(y) * width * image.channels);
  }
  return out;
}

Image resize_area_nonzero(const Image& map, int width, int height) {
  if (map.channels != 1) fail("resize_area_nonzero: expected one channel, got {}", map.channels);
  Image weighted(map.width, map.height, 1), mask(map.width, map.height, 1);
  for (std::size_t i = 0; i < map.pixels.size(); ++i) {
    const bool valid = map.pixels[i] != 0.0f;
    weighted.pixels[i] = valid ? map.pixels[i] : 0.0f;
    mask.pixels[i] = valid ? 1.0f : 0.0f;
  }
  const Image sum = resize_area(weighted, width, height), coverage = resize_area(mask, width, height);
  Image out(width, height, 1);
  for (std::size_t i = 0; i < out.pixels.size(); ++i)
    out.pixels[i] = coverage.pixels[i] >= 0.5f ? sum.pixels[i] / coverage.pixels[i] : 0.0f;
  return out;
}

namespace {

// Encodes in memory (format by the path's extension) and writes the bytes atomically, so that every write
// error is seen (OpenCV's file writers do not report one at close).
void write_encoded(const fs::path& path, const cv::Mat& m) {
  std::vector<unsigned char> bytes;
  try {
    if (!cv::imencode(path.extension().string(), m, bytes)) fail_file(path, "cannot encode image");
  } catch (const cv::Exception& e) {
    fail_file(path, "cannot encode image ({})", e.err);
  }
  write_file_atomic(path, std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
}

}  // namespace

void write_image(const fs::path& path, const Image& image) {
  if (image.channels != 1 && image.channels != 3 && image.channels != 4)
    fail_file(path, "cannot write an image with {} channels", image.channels);
  cv::Mat m;
  to_mat(image).convertTo(m, CV_8U, 255.0);  // saturates: clamps to [0,255] and rounds
  if (image.channels == 3) cv::cvtColor(m, m, cv::COLOR_RGB2BGR);
  if (image.channels == 4) cv::cvtColor(m, m, cv::COLOR_RGBA2BGRA);
  write_encoded(path, m);
}

void write_png16(const fs::path& path, const Image& image, float scale) {
  if (image.channels != 1) fail_file(path, "16-bit PNG output takes one channel, got {}", image.channels);
  cv::Mat m;
  to_mat(image).convertTo(m, CV_16U, scale);
  write_encoded(path, m);
}

}  // namespace d2gs
