// Tests for tessera/io/image_file.hpp: PNG/PGM round trips and clear errors on bad bytes.
#include <tessera/io/image_file.hpp>

#include <catch2/catch.hpp>

#include <unistd.h>

#include <filesystem>
#include <fstream>

namespace fs = std::filesystem;
using namespace tessera::io;
using Catch::Matchers::Contains;

namespace {

fs::path scratch(const std::string& name) {
  const fs::path dir =
      fs::temp_directory_path() / ("tessera_image_file_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  return dir / name;
}

Gray8 gradient(int w, int h) {
  Gray8 img;
  img.width = w;
  img.height = h;
  for (int r = 0; r < h; ++r)
    for (int c = 0; c < w; ++c)
      img.pixels.push_back(static_cast<std::uint8_t>((r * 31 + c * 7) & 255));
  return img;
}

}  // namespace

TEST_CASE("grey images survive PNG and PGM round trips", "[image_file]") {
  const Gray8 img = gradient(37, 21);
  const fs::path png = scratch("g.png"), pgm = scratch("g.pgm");
  writePngGray8(img, png);
  writePgmFile(img, pgm);
  for (const auto& path : {png, pgm}) {
    const Gray8 back = readGray8(path);
    CHECK(back.width == 37);
    CHECK(back.height == 21);
    CHECK(back.pixels == img.pixels);
  }
  const auto bytes = readFileBytes(png);
  const Rgb8 rgb = decodeRgb8(bytes, "g.png");  // grey PNG as RGB: three equal channels
  REQUIRE(rgb.pixels.size() == 37u * 21u * 3u);
  CHECK(rgb.pixels[3 * 40] == img.pixels[40]);
  CHECK(rgb.pixels[3 * 40 + 2] == img.pixels[40]);
}

TEST_CASE("bad image bytes give errors naming the file", "[image_file]") {
  const std::vector<std::uint8_t> garbage{'n', 'o', 't', ' ', 'a', 'n', ' ', 'i', 'm', 'g'};
  CHECK_THROWS_WITH(decodeRgb8(garbage, "x.jpg"),
                    Contains("x.jpg") && Contains("not a PNG or JPEG"));
  CHECK_THROWS_WITH(decodeGray16(garbage, "d.png"), Contains("d.png") && Contains("not a PNG"));
  // A JPEG signature followed by nonsense: libjpeg's error, not a crash.
  std::vector<std::uint8_t> jpeg{0xff, 0xd8, 0xff, 0xe0, 0x00, 0x10, 'J', 'F', 'I', 'F', 0, 1};
  CHECK_THROWS_AS(decodeRgb8(jpeg, "broken.jpg"), ImageFileError);
  // A truncated PNG.
  const fs::path png = scratch("t.png");
  writePngGray8(gradient(64, 64), png);
  auto bytes = readFileBytes(png);
  bytes.resize(bytes.size() / 2);
  CHECK_THROWS_WITH(decodeRgb8(bytes, "t.png"), Contains("t.png") && Contains("PNG"));
  // An 8-bit PNG is not a depth image.
  CHECK_THROWS_WITH(decodeGray16(readFileBytes(png), "g8.png"), Contains("1-channel 8U"));
  CHECK_THROWS_WITH(readGray8(scratch("missing.png")), Contains("missing.png"));
  std::ofstream(scratch("text.pgm")) << "P5\n2 x\n255\n";
  CHECK_THROWS_WITH(readGray8(scratch("text.pgm")), Contains("height"));
}
