// Image files without OpenCV: 8-bit grey PGM (P5/P2) and PNG, RGB PNG/JPEG, 16-bit grey PNG,
// through libpng and libjpeg. Shared by map files (actors/common), simulator worlds and the
// RGB-D dataset readers (hw). Keeping OpenCV out of these paths keeps it out of processes that
// only need image files: loading OpenCV's codecs costs ~47 MB of resident memory per process.
//
// Images are row-major with row 0 at the top. Every error is an ImageFileError whose message
// starts with the file (or the name given for in-memory bytes) and says what was expected.
#pragma once

#include <cstdint>
#include <filesystem>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

namespace tessera::io {

class ImageFileError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct Gray8 {
  int width = 0;
  int height = 0;
  std::vector<std::uint8_t> pixels;  ///< width*height
};
struct Rgb8 {
  int width = 0;
  int height = 0;
  std::vector<std::uint8_t> pixels;  ///< width*height*3, R G B
};
struct Gray16 {
  int width = 0;
  int height = 0;
  std::vector<std::uint16_t> pixels;  ///< width*height, the file's values unchanged
};

/// PGM, binary (P5) or ASCII (P2), maxval 1..255 (scaled to 0..255).
Gray8 readPgmFile(const std::filesystem::path& path);
void writePgmFile(const Gray8& image, const std::filesystem::path& path);
/// A PGM or PNG file (told apart by content) as 8-bit grey; colour PNGs are converted.
Gray8 readGray8(const std::filesystem::path& path);
void writePngGray8(const Gray8& image, const std::filesystem::path& path);

/// PNG or JPEG bytes (told apart by their signature) as 8-bit RGB; `name` names them in errors.
Rgb8 decodeRgb8(std::span<const std::uint8_t> bytes, const std::string& name);
/// A 16-bit single-channel PNG (depth images), values unchanged.
Gray16 decodeGray16(std::span<const std::uint8_t> bytes, const std::string& name);
/// The whole file; throws ImageFileError when it cannot be read.
std::vector<std::uint8_t> readFileBytes(const std::filesystem::path& path);

}  // namespace tessera::io
