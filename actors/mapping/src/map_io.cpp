#include <tessera/io/atomic_file.hpp>
#include <tessera/io/image_file.hpp>
#include <tessera/mapping/map_io.hpp>

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>

namespace tessera::mapping {
namespace fs = std::filesystem;

namespace {

constexpr std::uint8_t kOccupiedPixel = 0, kFreePixel = 254, kUnknownPixel = 205;

/// 12 significant digits: sub-nanometre for map sizes, and free of binary noise such as
/// 3 * 0.05 = 0.15000000000000002 that would otherwise show in every origin.
std::string numberText(double v) {
  std::array<char, 64> buf{};
  const auto res =
      std::to_chars(buf.data(), buf.data() + buf.size(), v, std::chars_format::general, 12);
  return std::string(buf.data(), res.ptr);
}

fs::path withSuffix(const fs::path& base, const char* suffix) {
  return fs::path(base.string() + suffix);
}

[[noreturn]] void fail(const fs::path& file, const std::string& what) {
  throw MapIoError(file.string() + ": " + what);
}

/// The shared image-file code reports ImageFileError; map IO reports MapIoError.
template <typename F>
auto mapIo(F&& f) {
  try {
    return f();
  } catch (const io::ImageFileError& e) {
    throw MapIoError(e.what());
  } catch (const io::FileWriteError& e) {
    throw MapIoError(e.what());
  }
}

// ---- YAML field access with errors that name the file, line and key ----

YAML::Node requireKey(const YAML::Node& root, const char* key, const fs::path& path) {
  const YAML::Node n = root[key];
  if (!n) fail(path, std::string("missing key '") + key + "'");
  return n;
}

std::string at(const YAML::Node& n, const fs::path& path) {
  return path.string() + ":" + std::to_string(n.Mark().line + 1);
}

double finiteNumber(const YAML::Node& n, const char* key, const fs::path& path) {
  double v = 0;
  try {
    v = n.as<double>();
  } catch (const YAML::Exception&) {
    throw MapIoError(at(n, path) + ": '" + key + "' must be a number");
  }
  if (!std::isfinite(v)) throw MapIoError(at(n, path) + ": '" + key + "' must be finite");
  return v;
}

}  // namespace

// ---------------------------------------------------------------------------------------------

void writePgm(const GrayImage& image, const fs::path& path) {
  mapIo([&] {
    io::writePgmFile(image, path);
    return 0;
  });
}

GrayImage readPgm(const fs::path& path) {
  return mapIo([&] { return io::readPgmFile(path); });
}

GrayImage renderTrinary(const grid::OccupancyMap& map, const MapSaveOptions& options) {
  GrayImage img;
  if (map.empty()) return img;
  img.width = map.width;
  img.height = map.height;
  img.pixels.resize(static_cast<std::size_t>(map.width) * map.height);
  for (int row = 0; row < map.height; ++row) {
    // Image row 0 is the top of the map, i.e. the last map row.
    std::uint8_t* out =
        img.pixels.data() + static_cast<std::size_t>(map.height - 1 - row) * map.width;
    for (int col = 0; col < map.width; ++col) {
      const std::int8_t v = map.at(col, row);
      const double p = v / 100.0;
      out[col] = v < 0                         ? kUnknownPixel
                 : p > options.occupied_thresh ? kOccupiedPixel
                 : p < options.free_thresh     ? kFreePixel
                                               : kUnknownPixel;
    }
  }
  return img;
}

SavedMap saveMap(const grid::OccupancyMap& map, const fs::path& base,
                 const MapSaveOptions& options) {
  if (map.empty()) fail(base, "saveMap: the map is empty (0 cells), nothing to write");
  if (map.cells.size() != static_cast<std::size_t>(map.width) * map.height)
    fail(base, "saveMap: map holds " + std::to_string(map.cells.size()) + " cells, expected " +
                   std::to_string(map.width) + "x" + std::to_string(map.height));
  if (!(std::isfinite(map.resolution) && map.resolution > 0))
    fail(base, "saveMap: resolution must be > 0");
  if (base.has_parent_path()) {
    std::error_code ec;
    fs::create_directories(base.parent_path(), ec);
    if (ec) fail(base.parent_path(), "cannot create directory: " + ec.message());
  }
  SavedMap saved{withSuffix(base, ".yaml"), withSuffix(base, ".pgm"), {}};
  const GrayImage img = renderTrinary(map, options);
  writePgm(img, saved.pgm);

  std::ostringstream yaml;
  yaml << "image: " << saved.pgm.filename().string() << "\n"
       << "mode: trinary\n"
       << "resolution: " << numberText(map.resolution) << "\n"
       << "origin: [" << numberText(map.origin.x) << ", " << numberText(map.origin.y) << ", "
       << numberText(map.origin.theta) << "]\n"
       << "negate: 0\n"
       << "occupied_thresh: " << numberText(options.occupied_thresh) << "\n"
       << "free_thresh: " << numberText(options.free_thresh) << "\n";
  mapIo([&] {
    io::writeFileAtomically(saved.yaml, yaml.str());
    return 0;
  });

  if (options.write_png) {
    saved.png = withSuffix(base, ".png");
    mapIo([&] {
      io::writePngGray8(img, saved.png);
      return 0;
    });
  }
  return saved;
}

grid::OccupancyMap loadMap(const fs::path& yaml_path) {
  YAML::Node root;
  try {
    root = YAML::LoadFile(yaml_path.string());
  } catch (const YAML::BadFile&) {
    fail(yaml_path, "cannot open for reading");
  } catch (const YAML::Exception& e) {
    fail(yaml_path, std::string("not valid YAML: ") + e.what());
  }
  if (!root.IsMap()) fail(yaml_path, "expected a YAML mapping with image, resolution, origin, ...");

  const YAML::Node image_node = requireKey(root, "image", yaml_path);
  if (!image_node.IsScalar() || image_node.Scalar().empty())
    throw MapIoError(at(image_node, yaml_path) + ": 'image' must be a file name");
  const double resolution =
      finiteNumber(requireKey(root, "resolution", yaml_path), "resolution", yaml_path);
  if (resolution <= 0)
    throw MapIoError(at(root["resolution"], yaml_path) + ": 'resolution' must be > 0");

  const YAML::Node origin = requireKey(root, "origin", yaml_path);
  if (!origin.IsSequence() || origin.size() != 3)
    throw MapIoError(at(origin, yaml_path) + ": 'origin' must be a list [x, y, yaw]");
  const double ox = finiteNumber(origin[0], "origin", yaml_path);
  const double oy = finiteNumber(origin[1], "origin", yaml_path);
  const double oyaw = finiteNumber(origin[2], "origin", yaml_path);

  const YAML::Node negate_node = requireKey(root, "negate", yaml_path);
  const double negate = finiteNumber(negate_node, "negate", yaml_path);
  if (negate != 0 && negate != 1)
    throw MapIoError(at(negate_node, yaml_path) + ": 'negate' must be 0 or 1");
  const double occ =
      finiteNumber(requireKey(root, "occupied_thresh", yaml_path), "occupied_thresh", yaml_path);
  const double free =
      finiteNumber(requireKey(root, "free_thresh", yaml_path), "free_thresh", yaml_path);
  if (!(0 <= free && free < occ && occ <= 1))
    fail(yaml_path, "thresholds must satisfy 0 <= free_thresh < occupied_thresh <= 1");

  std::string mode = "trinary";
  if (const YAML::Node m = root["mode"]) {
    mode = m.IsScalar() ? m.Scalar() : "";
    if (mode != "trinary" && mode != "scale" && mode != "raw")
      throw MapIoError(at(m, yaml_path) + ": 'mode' must be trinary, scale or raw");
  }

  fs::path image_path = image_node.Scalar();
  if (image_path.is_relative()) image_path = yaml_path.parent_path() / image_path;
  std::string ext = image_path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  const GrayImage img =
      ext == ".pgm" ? readPgm(image_path) : mapIo([&] { return io::readGray8(image_path); });

  grid::OccupancyMap map;
  map.resolution = resolution;
  map.width = img.width;
  map.height = img.height;
  map.origin = Pose2(ox, oy, oyaw);
  map.cells.resize(img.pixels.size());
  for (int r = 0; r < img.height; ++r) {
    const std::uint8_t* in = img.pixels.data() + static_cast<std::size_t>(r) * img.width;
    const int row = img.height - 1 - r;
    for (int col = 0; col < img.width; ++col) {
      const int v = in[col];
      std::int8_t cell;
      if (mode == "raw") {
        cell = v <= 100 ? static_cast<std::int8_t>(v) : grid::OccupancyMap::kUnknown;
      } else {
        const double p = negate != 0 ? v / 255.0 : (255.0 - v) / 255.0;
        if (p > occ) {
          cell = 100;
        } else if (p < free) {
          cell = 0;
        } else if (mode == "scale") {
          cell = static_cast<std::int8_t>(std::lround(99.0 * (p - free) / (occ - free)));
        } else {
          cell = grid::OccupancyMap::kUnknown;
        }
      }
      map.at(col, row) = cell;
    }
  }
  return map;
}

}  // namespace tessera::mapping
