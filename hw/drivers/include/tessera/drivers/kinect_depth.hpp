// The Kinect v1's raw depth and how colour and depth frames are paired
// (docs/architecture.md#device-drivers).
//
// The Kinect v1 does not measure depth: it measures the disparity of a projected infrared dot
// pattern against a reference image, an 11-bit value per pixel of its 640 x 480 depth (IR)
// camera, 2047 meaning no reading. Depth is inversely proportional to disparity:
//   z = 8 * baseline * focal / (disparity_offset - d)      [m]
// (the factor 8: disparities are in 1/8 px). KinectDepthModel holds the three constants (nominal
// values of the device family; a calibrated unit overrides them) and converts both ways;
// KinectDepthConverter turns a whole raw frame into 16-bit depth at a given scale through a
// 2048-entry table. A reading outside [min_depth_m, max_depth_m] becomes 0, "no reading", the
// convention of RgbdFrame's 16UC1 depth.
//
// Colour and depth arrive as separate streams at 30 Hz each. RgbdPairer pairs them by their
// stamps (the driver's, from the device's frame counter): a colour frame with the depth frame
// nearest in time, within max_gap; a frame that finds no partner is dropped and counted.
//
// Plain C++: no libfreenect here (hw/drivers/src/freenect_camera.cpp talks to it).
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

namespace tessera::drivers {

struct KinectDepthModel {
  double baseline_m = 0.075;       ///< IR projector to IR camera
  double focal_px = 580;           ///< IR camera focal length
  double disparity_offset = 1090;  ///< d at infinite depth, in 1/8 px
  double min_depth_m = 0.4;        ///< nearer readings are dropped (the sensor's blind zone)
  double max_depth_m = 8.0;        ///< farther readings are dropped (too coarse to use)

  static constexpr int kNoReading = 2047;  ///< the raw value of a pixel without a reading

  template <class V>
  void visit(V& v) {
    v("baseline_m", baseline_m, "[m] IR projector to IR camera (Kinect v1: 0.075)");
    v("focal_px", focal_px, "[px] IR camera focal length (Kinect v1: 580)");
    v("disparity_offset", disparity_offset, "raw disparity at infinite depth (Kinect v1: 1090)");
    v("min_depth_m", min_depth_m, "[m] nearer readings are dropped");
    v("max_depth_m", max_depth_m, "[m] farther readings are dropped");
  }

  /// Throws std::invalid_argument naming the value when a constant is not finite or positive,
  /// or the depth range is empty.
  void validate() const;
  /// Depth [m] of raw disparity `d`; nullopt for kNoReading, d outside [0, 2047], or a depth
  /// outside [min_depth_m, max_depth_m].
  std::optional<double> metres(int d) const;
  /// The raw disparity whose depth is nearest `z` [m]; kNoReading for a depth outside the
  /// range (or not finite). The inverse of metres() up to rounding.
  int disparity(double z) const;
};

class KinectDepthConverter {
 public:
  /// `units_per_metre`: scale of the 16-bit output (1000: millimetres). Throws
  /// std::invalid_argument for an invalid model or scale, or a range the scale cannot hold.
  KinectDepthConverter(const KinectDepthModel& model, double units_per_metre);

  /// Converts `raw` (11-bit disparities, one per pixel) into `out` (same size). Returns the
  /// number of pixels whose raw value exceeded 11 bits (a corrupt transfer; they become 0).
  std::size_t convert(std::span<const std::uint16_t> raw, std::span<std::uint16_t> out) const;

 private:
  std::vector<std::uint16_t> table_;  // 2048 entries
};

/// One frame of one stream, waiting for its partner.
struct KinectImage {
  std::int64_t stamp_ns = 0;         ///< host time the frame was taken
  std::vector<std::uint8_t> bytes;   ///< a colour frame: RGB bytes
  std::vector<std::uint16_t> depth;  ///< a depth frame: its values (the driver's: millimetres)
};

class RgbdPairer {
 public:
  explicit RgbdPairer(std::int64_t max_gap_ns);

  struct Pair {
    KinectImage color, depth;
  };
  /// Adds a frame of either stream; returns a pair when it completes one. A waiting frame of
  /// the same stream is replaced (dropped) by the newer one; so is a waiting frame of the other
  /// stream that is more than max_gap older.
  std::optional<Pair> addColor(KinectImage image);
  std::optional<Pair> addDepth(KinectImage image);
  void reset();  ///< forgets waiting frames (a reconnect)

  std::int64_t paired() const { return paired_; }
  std::int64_t dropped() const { return dropped_; }

 private:
  std::optional<Pair> add(KinectImage image, std::optional<KinectImage>& mine,
                          std::optional<KinectImage>& other, bool is_color);

  std::int64_t max_gap_ns_;
  std::optional<KinectImage> color_, depth_;
  std::int64_t paired_ = 0, dropped_ = 0;
};

}  // namespace tessera::drivers
