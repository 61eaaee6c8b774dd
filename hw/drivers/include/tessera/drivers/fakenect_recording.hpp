// Recordings in the format of libfreenect's own player, fakenect (docs/architecture.md#device-
// drivers): a folder with INDEX.txt, one file name per line, in playback order. A name starts
// "TYPE-TIME-TIMESTAMP": TYPE d (depth), r (colour) or a (accelerometer), TIME the host time [s]
// it was recorded at (playback keeps the gaps), TIMESTAMP the device's 32-bit frame counter.
// A depth file is a one-line PGM header and 640 x 480 raw 11-bit disparities (uint16, host
// order); a colour file a one-line PPM header and 640 x 480 RGB bytes.
//
// Debian's fakenect library (libfreenect0.5, /usr/lib/<arch>/fakenect/) plays such a folder in
// place of the device when it is loaded instead of libfreenect and FAKENECT_PATH names the folder.
// It ends the process on a missing or short file, so the driver checks a recording with
// checkFakenectRecording() before handing it over. FakenectRecordingWriter makes recordings
// (`tessera emulate kinect` converts an RGB-D dataset into one).
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <span>
#include <stdexcept>
#include <string>

namespace tessera::drivers {

inline constexpr int kKinectWidth = 640;
inline constexpr int kKinectHeight = 480;

/// A recording fakenect cannot play; the message names the file (and line) and what is wrong.
class FakenectRecordingError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct FakenectRecordingInfo {
  std::size_t depth_frames = 0, color_frames = 0, accel_samples = 0;
  double duration_s = 0;  ///< last TIME - first TIME
};

/// Checks every line of `folder`/INDEX.txt the way fakenect will read it: the name's type and
/// times, the file's presence, its one-line header and that it holds a whole frame. Throws
/// FakenectRecordingError on the first problem, or when there is no depth or no colour frame.
FakenectRecordingInfo checkFakenectRecording(const std::filesystem::path& folder);

class FakenectRecordingWriter {
 public:
  /// Creates `folder` (which must not exist or be empty) and its INDEX.txt. Throws
  /// FakenectRecordingError. A frame equal to the previous one of its stream is stored as a
  /// hard link to it (a still scene, a benchmark's minutes of frames, cost no disk).
  explicit FakenectRecordingWriter(const std::filesystem::path& folder);

  /// `raw`: 640 x 480 disparities (<= 2047). `time_s`: must not decrease from entry to entry.
  void addDepth(double time_s, std::uint32_t timestamp, std::span<const std::uint16_t> raw);
  /// `rgb`: 640 x 480 x 3 bytes, R G B.
  void addColor(double time_s, std::uint32_t timestamp, std::span<const std::uint8_t> rgb);
  std::size_t entries() const { return entries_; }

 private:
  void add(char type, double time_s, std::uint32_t timestamp, const std::string& header,
           const void* data, std::size_t bytes);

  std::filesystem::path folder_;
  std::ofstream index_;
  std::size_t entries_ = 0;
  double last_time_ = 0;
  struct Last {
    std::filesystem::path file;
    std::string bytes;
  };
  Last last_depth_, last_color_;
};

}  // namespace tessera::drivers
