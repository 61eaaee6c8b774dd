// libpng (simplified API) and libjpeg behind tessera/io/image_file.hpp.
#include <tessera/io/atomic_file.hpp>
#include <tessera/io/image_file.hpp>

#include <jpeglib.h>
#include <png.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <csetjmp>
#include <cstdio>
#include <fstream>
#include <iterator>

namespace tessera::io {
namespace fs = std::filesystem;

namespace {

// Refuse absurd headers before allocating (2^28 pixels = 256 MB, ~13 km square at 5 cm).
constexpr long long kMaxPixels = 1LL << 28;

[[noreturn]] void fail(const fs::path& file, const std::string& what) {
  throw ImageFileError(file.string() + ": " + what);
}

/// Writing goes through AtomicFile; its errors are reported as ImageFileError like the others.
template <typename F>
void asImageFileError(F&& write) {
  try {
    write();
  } catch (const FileWriteError& e) {
    throw ImageFileError(e.what());
  }
}

std::string readWholeFile(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(path, "cannot open for reading");
  std::string data((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) fail(path, "read error");
  return data;
}

/// Tokenizer for the PGM header: whitespace-separated tokens, '#' comments to end of line.
class PgmHeader {
 public:
  PgmHeader(const std::string& data, const fs::path& path) : data_(data), path_(path) {}

  std::string token(const char* what) {
    skipSpaceAndComments();
    const std::size_t start = pos_;
    while (pos_ < data_.size() && !std::isspace(static_cast<unsigned char>(data_[pos_])) &&
           data_[pos_] != '#')
      ++pos_;
    if (start == pos_)
      fail(path_, std::string("bad PGM header: expected ") + what + ", found end of file");
    return data_.substr(start, pos_ - start);
  }

  long long positive(const char* what) {
    const std::string t = token(what);
    long long v = 0;
    const auto [ptr, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
    if (ec != std::errc() || ptr != t.data() + t.size() || v <= 0)
      fail(path_, std::string("bad PGM header: expected ") + what +
                      " (a positive integer), found '" + t + "'");
    return v;
  }

  /// After maxval exactly one whitespace byte separates the header from binary pixels.
  std::size_t binaryStart() {
    if (pos_ >= data_.size() || !std::isspace(static_cast<unsigned char>(data_[pos_])))
      fail(path_, "bad PGM header: expected one whitespace byte after maxval");
    return pos_ + 1;
  }
  std::size_t position() const { return pos_; }

 private:
  void skipSpaceAndComments() {
    while (pos_ < data_.size()) {
      if (std::isspace(static_cast<unsigned char>(data_[pos_]))) {
        ++pos_;
      } else if (data_[pos_] == '#') {
        while (pos_ < data_.size() && data_[pos_] != '\n') ++pos_;
      } else {
        break;
      }
    }
  }
  const std::string& data_;
  const fs::path& path_;
  std::size_t pos_ = 0;
};

bool isPng(std::span<const std::uint8_t> b) {
  return b.size() >= 8 && png_sig_cmp(b.data(), 0, 8) == 0;
}
bool isJpeg(std::span<const std::uint8_t> b) {
  return b.size() >= 3 && b[0] == 0xff && b[1] == 0xd8 && b[2] == 0xff;
}

/// Decodes PNG bytes into `format` (PNG_FORMAT_*); returns the sample buffer.
template <typename Sample>
std::vector<Sample> decodePng(std::span<const std::uint8_t> bytes, const std::string& name,
                              png_uint_32 format, int& width, int& height) {
  png_image image{};
  image.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_memory(&image, bytes.data(), bytes.size()))
    fail(name, std::string("cannot decode PNG: ") + image.message);
  if (static_cast<long long>(image.width) * image.height > kMaxPixels) {
    png_image_free(&image);
    fail(name, "PNG of " + std::to_string(image.width) + "x" + std::to_string(image.height) +
                   " pixels is larger than supported");
  }
  image.format = format;
  std::vector<Sample> out(PNG_IMAGE_SIZE(image) / sizeof(Sample));
  if (!png_image_finish_read(&image, nullptr, out.data(), 0, nullptr))
    fail(name, std::string("cannot decode PNG: ") + image.message);
  width = static_cast<int>(image.width);
  height = static_cast<int>(image.height);
  return out;
}

struct JpegError {
  jpeg_error_mgr mgr;
  std::jmp_buf jump;
  char message[JMSG_LENGTH_MAX];
};

void onJpegError(j_common_ptr info) {
  auto* err = reinterpret_cast<JpegError*>(info->err);
  (*info->err->format_message)(info, err->message);
  std::longjmp(err->jump, 1);
}

Rgb8 decodeJpeg(std::span<const std::uint8_t> bytes, const std::string& name) {
  jpeg_decompress_struct info{};
  JpegError err{};
  info.err = jpeg_std_error(&err.mgr);
  err.mgr.error_exit = onJpegError;
  // Recoverable damage (e.g. a premature end) decodes what is there; the file checks of the
  // callers decide about truncation, so libjpeg's warnings stay off stderr.
  err.mgr.output_message = [](j_common_ptr) {};
  // Only plain data lives across setjmp: the image is returned through this pointer.
  Rgb8* result = new Rgb8;
  if (setjmp(err.jump)) {
    jpeg_destroy_decompress(&info);
    delete result;
    fail(name, std::string("cannot decode JPEG: ") + err.message);
  }
  jpeg_create_decompress(&info);
  jpeg_mem_src(&info, bytes.data(), static_cast<unsigned long>(bytes.size()));
  jpeg_read_header(&info, TRUE);
  info.out_color_space = JCS_RGB;
  jpeg_start_decompress(&info);
  if (static_cast<long long>(info.output_width) * info.output_height > kMaxPixels)
    std::longjmp(err.jump, 1);
  result->width = static_cast<int>(info.output_width);
  result->height = static_cast<int>(info.output_height);
  result->pixels.resize(static_cast<std::size_t>(result->width) * result->height * 3);
  while (info.output_scanline < info.output_height) {
    JSAMPROW row = result->pixels.data() + static_cast<std::size_t>(info.output_scanline) *
                                               static_cast<std::size_t>(result->width) * 3;
    jpeg_read_scanlines(&info, &row, 1);
  }
  jpeg_finish_decompress(&info);
  jpeg_destroy_decompress(&info);
  Rgb8 out = std::move(*result);
  delete result;
  return out;
}

}  // namespace

std::vector<std::uint8_t> readFileBytes(const fs::path& path) {
  const std::string data = readWholeFile(path);
  return {data.begin(), data.end()};
}

void writePgmFile(const Gray8& image, const fs::path& path) {
  if (image.pixels.size() != static_cast<std::size_t>(image.width) * image.height)
    fail(path, "image holds " + std::to_string(image.pixels.size()) + " pixels, expected " +
                   std::to_string(static_cast<std::size_t>(image.width) * image.height));
  const std::string header = "P5\n# tessera occupancy map\n" + std::to_string(image.width) + ' ' +
                             std::to_string(image.height) + "\n255\n";
  asImageFileError([&] {
    AtomicFile out(path);
    out.write(header);
    out.write({reinterpret_cast<const char*>(image.pixels.data()), image.pixels.size()});
    out.commit();
  });
}

Gray8 readPgmFile(const fs::path& path) {
  const std::string data = readWholeFile(path);
  PgmHeader header(data, path);
  const std::string magic = header.token("magic 'P5' or 'P2'");
  if (magic != "P5" && magic != "P2")
    fail(path, "bad PGM header: expected magic 'P5' or 'P2', found '" + magic.substr(0, 16) + "'");
  const long long width = header.positive("width");
  const long long height = header.positive("height");
  const long long maxval = header.positive("maxval");
  if (maxval > 255)
    fail(path,
         "maxval " + std::to_string(maxval) + " (16-bit PGM) is not supported; expected 1..255");
  if (width * height > kMaxPixels)
    fail(path, "image of " + std::to_string(width) + "x" + std::to_string(height) +
                   " pixels is larger than supported");
  Gray8 img;
  img.width = static_cast<int>(width);
  img.height = static_cast<int>(height);
  const std::size_t n = static_cast<std::size_t>(width * height);
  img.pixels.resize(n);
  if (magic == "P5") {
    const std::size_t start = header.binaryStart();
    const std::size_t available = data.size() - std::min(start, data.size());
    if (available < n)
      fail(path, "truncated pixel data: expected " + std::to_string(n) + " bytes for " +
                     std::to_string(width) + "x" + std::to_string(height) + ", found " +
                     std::to_string(available));
    std::copy_n(reinterpret_cast<const std::uint8_t*>(data.data() + start), n, img.pixels.begin());
  } else {
    for (std::size_t i = 0; i < n; ++i) {
      const std::string t = header.token("a pixel value");
      int v = 0;
      const auto [ptr, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
      if (ec != std::errc() || ptr != t.data() + t.size() || v < 0 || v > maxval)
        fail(path, "bad pixel " + std::to_string(i) + ": expected 0.." + std::to_string(maxval) +
                       ", found '" + t + "'");
      img.pixels[i] = static_cast<std::uint8_t>(v);
    }
  }
  for (std::size_t i = 0; i < n && maxval != 255; ++i)
    img.pixels[i] = static_cast<std::uint8_t>(std::min<long long>(
        255, (static_cast<long long>(img.pixels[i]) * 255 + maxval / 2) / maxval));
  return img;
}

Gray8 readGray8(const fs::path& path) {
  const std::vector<std::uint8_t> bytes = readFileBytes(path);
  if (bytes.size() >= 2 && bytes[0] == 'P' && (bytes[1] == '5' || bytes[1] == '2'))
    return readPgmFile(path);
  if (!isPng(bytes)) fail(path, "not a PGM or PNG image");
  Gray8 img;
  img.pixels =
      decodePng<std::uint8_t>(bytes, path.string(), PNG_FORMAT_GRAY, img.width, img.height);
  return img;
}

void writePngGray8(const Gray8& image, const fs::path& path) {
  if (image.pixels.size() != static_cast<std::size_t>(image.width) * image.height)
    fail(path, "image holds " + std::to_string(image.pixels.size()) + " pixels, expected " +
                   std::to_string(static_cast<std::size_t>(image.width) * image.height));
  png_image png{};
  png.version = PNG_IMAGE_VERSION;
  png.width = static_cast<png_uint_32>(image.width);
  png.height = static_cast<png_uint_32>(image.height);
  png.format = PNG_FORMAT_GRAY;
  // Encoded in memory, so that the file is written (and replaced) in one piece.
  png_alloc_size_t size = 0;
  if (!png_image_write_get_memory_size(png, size, 0, image.pixels.data(), 0, nullptr))
    fail(path, std::string("PNG encoding failed: ") + png.message);
  std::string bytes(size, '\0');
  if (!png_image_write_to_memory(&png, bytes.data(), &size, 0, image.pixels.data(), 0, nullptr))
    fail(path, std::string("PNG encoding failed: ") + png.message);
  bytes.resize(size);
  asImageFileError([&] { writeFileAtomically(path, bytes); });
}

Rgb8 decodeRgb8(std::span<const std::uint8_t> bytes, const std::string& name) {
  if (isJpeg(bytes)) return decodeJpeg(bytes, name);
  if (!isPng(bytes)) fail(name, "cannot decode: not a PNG or JPEG image");
  Rgb8 img;
  img.pixels = decodePng<std::uint8_t>(bytes, name, PNG_FORMAT_RGB, img.width, img.height);
  return img;
}

Gray16 decodeGray16(std::span<const std::uint8_t> bytes, const std::string& name) {
  if (!isPng(bytes))
    fail(name, "cannot decode: not a PNG image (expected a 16-bit single-channel PNG)");
  png_image probe{};
  probe.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_memory(&probe, bytes.data(), bytes.size()))
    fail(name, std::string("cannot decode PNG: ") + probe.message);
  const png_uint_32 format = probe.format;
  png_image_free(&probe);
  // A 16-bit file without colour-space chunks is linear: read back as linear grey, its values
  // come out unchanged. Anything else is not a depth image.
  if ((format & PNG_FORMAT_FLAG_LINEAR) == 0 || (format & PNG_FORMAT_FLAG_COLOR) != 0 ||
      (format & PNG_FORMAT_FLAG_ALPHA) != 0)
    fail(name, "expected a single-channel 16-bit PNG, found " +
                   std::to_string(PNG_IMAGE_SAMPLE_CHANNELS(format)) + "-channel " +
                   ((format & PNG_FORMAT_FLAG_LINEAR) != 0 ? "16U" : "8U"));
  Gray16 img;
  img.pixels = decodePng<std::uint16_t>(bytes, name, PNG_FORMAT_LINEAR_Y, img.width, img.height);
  return img;
}

}  // namespace tessera::io
