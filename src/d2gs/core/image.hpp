#pragma once
// Images in memory: float32, interleaved channels, row-major (height x width x channels), values in
// [0, 1]. File I/O goes through OpenCV's codecs (PNG, JPEG, ...); colour order in memory is RGB(A).
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string_view>
#include <vector>

namespace d2gs {

struct Image {
  int width = 0;
  int height = 0;
  int channels = 0;
  std::vector<float> pixels;  // size width * height * channels

  Image() = default;
  Image(int w, int h, int c, float fill = 0.0f)
      : width(w), height(h), channels(c), pixels(static_cast<std::size_t>(w) * h * c, fill) {}
  float& at(int x, int y, int c) { return pixels[(static_cast<std::size_t>(y) * width + x) * channels + c]; }
  float at(int x, int y, int c) const {
    return pixels[(static_cast<std::size_t>(y) * width + x) * channels + c];
  }
  bool empty() const { return pixels.empty(); }
};

struct ImageSize {
  int width = 0;
  int height = 0;
};

// The largest frame d2gs decodes (2^28 pixels, e.g. 16384 x 16384; a 200-megapixel photo fits). A larger
// declared size (a few kilobytes of PNG or JPEG can declare gigapixels) is refused from the header, before
// any pixel memory is taken, by read_image, decode_image and read_image_size.
inline constexpr std::int64_t kMaxImagePixels = std::int64_t{1} << 28;

// Called with the path of every image file read_image() decodes (nullptr: none). Lets tests prove that a
// command reads only the views it may use (the sparse-view protocol: no test view in training or
// initialisation). Set it before, and clear it after, the code under observation; not thread-safe.
using ImageReadObserver = std::function<void(const std::filesystem::path&)>;
void set_image_read_observer(ImageReadObserver observer);

// Decodes an image file to float [0,1] RGB or RGBA (8- and 16-bit sources). Errors name the file. A
// truncated or corrupt file is an error, never a partly grey image: PNG by its checksums, JPEG by a
// check that libjpeg reads the whole stream without a warning.
Image read_image(const std::filesystem::path& path);
// The same from the bytes of a file; `source` names it in errors.
Image decode_image(std::string_view bytes, const std::filesystem::path& source);
// Reads only the header of a PNG or JPEG file (falls back to decoding other formats).
ImageSize read_image_size(const std::filesystem::path& path);
// Area (box-average) resampling to the given size, as OpenCV's INTER_AREA.
Image resize_area(const Image& image, int width, int height);
// Area resampling of a one-channel map whose 0 means "no value" (depth maps): each output pixel is the
// area-weighted mean of the non-zero values under it, or 0 when they cover less than half of its area.
Image resize_area_nonzero(const Image& map, int width, int height);
// Writes 8-bit PNG/JPEG (by extension) atomically; values are clamped to [0,1] and rounded.
void write_image(const std::filesystem::path& path, const Image& image);
// Writes a single-channel image as a 16-bit PNG atomically: value v is stored as round(v * scale).
void write_png16(const std::filesystem::path& path, const Image& image, float scale);

}  // namespace d2gs
