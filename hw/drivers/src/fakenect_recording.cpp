#include <tessera/drivers/fakenect_recording.hpp>

#include <tessera/drivers/session_text.hpp>

#include <cmath>
#include <cstdio>
#include <string_view>
#include <vector>

namespace tessera::drivers {

namespace fakenect_detail {

constexpr std::size_t kDepthBytes = std::size_t{kKinectWidth} * kKinectHeight * 2;
constexpr std::size_t kColorBytes = std::size_t{kKinectWidth} * kKinectHeight * 3;

[[noreturn]] void fail(const std::filesystem::path& file, std::size_t line,
                       const std::string& what) {
  std::string m = file.string();
  if (line > 0) m.append(":").append(std::to_string(line));
  m.append(": ").append(what);
  throw FakenectRecordingError(m);
}

struct NameFields {
  char type = 0;
  double time_s = 0;
};

/// Parses "T-TIME-TIMESTAMP..." as fakenect's sscanf does, but strictly.
bool parseName(const std::string& name, NameFields& out) {
  if (name.size() < 5 || name[1] != '-') return false;
  out.type = name[0];
  const char* p = name.c_str() + 2;
  char* end = nullptr;
  out.time_s = std::strtod(p, &end);
  if (end == p || *end != '-' || !std::isfinite(out.time_s) || out.time_s < 0) return false;
  p = end + 1;
  if (*p < '0' || *p > '9') return false;
  const unsigned long long stamp = std::strtoull(p, &end, 10);
  return stamp <= 0xffffffffULL;
}

}  // namespace fakenect_detail

FakenectRecordingInfo checkFakenectRecording(const std::filesystem::path& folder) {
  namespace d = fakenect_detail;
  const auto index_path = folder / "INDEX.txt";
  std::ifstream index(index_path, std::ios::binary);
  if (!index)
    d::fail(index_path, 0, "cannot be opened (a fakenect recording is a folder with INDEX.txt)");
  FakenectRecordingInfo info;
  std::string line;
  std::size_t n = 0;
  double first = 0, last = 0;
  bool ended = false;
  while (std::getline(index, line)) {
    ++n;
    if (line.empty()) {
      ended = true;  // fakenect stops at an empty line: anything after it would never play
      continue;
    }
    if (ended) d::fail(index_path, n, "follows an empty line, where playback would already stop");
    if (!line.empty() && line.back() == '\r')
      d::fail(index_path, n, "ends in a carriage return (fakenect would look for a file named so)");
    d::NameFields f;
    if (!d::parseName(line, f))
      d::fail(index_path, n,
              "'" + line +
                  "' is not TYPE-TIME-TIMESTAMP (e.g. d-12.033-4211.pgm) with a finite "
                  "time >= 0 and a 32-bit timestamp");
    if (f.type != 'd' && f.type != 'r' && f.type != 'a')
      d::fail(index_path, n, std::string("type '") + f.type + "' is none of d, r, a");
    if (n > 1 && f.time_s < last)
      d::fail(index_path, n,
              "time " + decimal(f.time_s) + " s is earlier than the previous line's " +
                  decimal(last) + " s");
    if (info.depth_frames + info.color_frames + info.accel_samples == 0) first = f.time_s;
    last = f.time_s;
    const auto file = folder / line;
    std::error_code ec;
    const auto size = std::filesystem::file_size(file, ec);
    if (ec) d::fail(file, 0, "listed in INDEX.txt line " + std::to_string(n) + " is missing");
    if (f.type == 'a') {
      ++info.accel_samples;
      continue;
    }
    std::ifstream in(file, std::ios::binary);
    std::string header;
    if (!std::getline(in, header) || in.eof())
      d::fail(file, 0, "has no one-line header ending in a newline");
    const std::string magic = f.type == 'd' ? "P5" : "P6";
    if (header.rfind(magic, 0) != 0)
      d::fail(file, 0, "header '" + header + "' is not a " + magic + " header");
    const std::size_t need = f.type == 'd' ? d::kDepthBytes : d::kColorBytes;
    const std::size_t have = static_cast<std::size_t>(size) - header.size() - 1;
    if (have < need)
      d::fail(file, 0,
              "holds " + std::to_string(have) + " bytes of image, a 640 x 480 " +
                  (f.type == 'd' ? std::string("depth frame needs ") : "colour frame needs ") +
                  std::to_string(need) + " (truncated?)");
    ++(f.type == 'd' ? info.depth_frames : info.color_frames);
  }
  if (info.depth_frames == 0 || info.color_frames == 0)
    d::fail(index_path, 0,
            "lists " + std::to_string(info.depth_frames) + " depth and " +
                std::to_string(info.color_frames) +
                " colour frames; a recording needs both streams");
  info.duration_s = last - first;
  return info;
}

FakenectRecordingWriter::FakenectRecordingWriter(const std::filesystem::path& folder)
    : folder_(folder) {
  std::error_code ec;
  if (std::filesystem::exists(folder_, ec) && !std::filesystem::is_empty(folder_, ec))
    fakenect_detail::fail(folder_, 0, "exists and is not empty; a recording needs a new folder");
  std::filesystem::create_directories(folder_, ec);
  if (ec) fakenect_detail::fail(folder_, 0, "cannot be created: " + ec.message());
  index_.open(folder_ / "INDEX.txt", std::ios::binary);
  if (!index_) fakenect_detail::fail(folder_ / "INDEX.txt", 0, "cannot be written");
}

void FakenectRecordingWriter::addDepth(double time_s, std::uint32_t timestamp,
                                       std::span<const std::uint16_t> raw) {
  if (raw.size() * 2 != fakenect_detail::kDepthBytes)
    throw std::invalid_argument("addDepth: " + std::to_string(raw.size()) +
                                " pixels, a Kinect depth frame has 640 x 480");
  for (const auto d : raw)
    if (d > 2047)
      throw std::invalid_argument("addDepth: disparity " + std::to_string(d) + " exceeds 11 bits");
  add('d', time_s, timestamp, "P5 640 480 65535\n", raw.data(), raw.size() * 2);
}

void FakenectRecordingWriter::addColor(double time_s, std::uint32_t timestamp,
                                       std::span<const std::uint8_t> rgb) {
  if (rgb.size() != fakenect_detail::kColorBytes)
    throw std::invalid_argument("addColor: " + std::to_string(rgb.size()) +
                                " bytes, a Kinect colour frame has 640 x 480 x 3");
  add('r', time_s, timestamp, "P6 640 480 255\n", rgb.data(), rgb.size());
}

void FakenectRecordingWriter::add(char type, double time_s, std::uint32_t timestamp,
                                  const std::string& header, const void* data, std::size_t bytes) {
  if (!std::isfinite(time_s) || time_s < 0 || (entries_ > 0 && time_s < last_time_))
    throw std::invalid_argument("FakenectRecordingWriter: time " + decimal(time_s) +
                                " s is not finite, negative or earlier than the previous entry's");
  char name[96];
  std::snprintf(name, sizeof name, "%c-%.6f-%u.%s", type, time_s, timestamp,
                type == 'd' ? "pgm" : "ppm");
  Last& last = type == 'd' ? last_depth_ : last_color_;
  const std::string_view content(static_cast<const char*>(data), bytes);
  std::error_code ec;
  if (!last.file.empty() && last.bytes == content) {
    std::filesystem::create_hard_link(last.file, folder_ / name, ec);
    if (ec) fakenect_detail::fail(folder_ / name, 0, "cannot be linked: " + ec.message());
  } else {
    std::ofstream out(folder_ / name, std::ios::binary);
    out.write(header.data(), static_cast<std::streamsize>(header.size()));
    out.write(content.data(), static_cast<std::streamsize>(bytes));
    if (!out) fakenect_detail::fail(folder_ / name, 0, "cannot be written (disk full?)");
    last.file = folder_ / name;
    last.bytes.assign(content);
  }
  index_ << name << '\n';
  index_.flush();
  if (!index_) fakenect_detail::fail(folder_ / "INDEX.txt", 0, "cannot be written");
  ++entries_;
  last_time_ = time_s;
}

}  // namespace tessera::drivers
