// Camera calibration files: the environment cameras' floor -> pixel homographies, each in the SLAM
// submap it was calibrated in (docs/algorithms.md#camera-network-calibration), as the
// camera_network_slam actor writes them (calibrations_file, camera_calibrations.yaml by default)
// and as a later run or a tool reads them back.
//
// Format (YAML): a top-level `cameras:` list (nothing else at the top level), one mapping per
// camera with exactly these keys:
//
//   cameras:
//     - id: 0                 # camera id, >= 0, unique in the file
//       submap: 1             # the submap whose frame the floor points are in, >= 0
//       stamp_ns: 123000000   # end of the visit it was calibrated from [ns]
//       homography: [h00, h01, h02, h10, h11, h12, h20, h21, h22]   # floor [m] -> pixel [px],
//                             # row-major, finite and non-singular (h22 = 1 as estimated)
//       rms_px: 0.8           # inliers' reprojection RMS [px], >= 0
//       coverage: 0.21        # inlier pixels' convex hull / image area, 0..1
//       condition: 3.2e3      # σ_max / σ_8 of the normalised DLT matrix, >= 0
//       pairs: 402            # (marker position, pixel) pairs, >= 0
//       inliers: 398          # 0..pairs
//
// The writer puts the cameras by increasing id and numbers in their shortest round-trip form, so
// write -> read is exact. It checks the records as the reader does
// (tessera::floorCameraCalibrationProblem) and writes atomically
// (tessera/io/atomic_file.hpp): the file is either the previous one or the complete new one.
//
// Errors: CameraCalibrationFileError, whose message names the file (and line, when known), the
// camera entry (cameras[index], with its id once read) and the field, says what was expected and
// what was found: a missing or empty file, text that is not YAML (e.g. a truncated file), a
// missing or unknown key, a wrong type, a non-finite number, a homography that is not 9 numbers or
// is singular, a negative id, a camera listed twice. E.g.
//   out/camera_calibrations.yaml:14: cameras[1] (camera 3): rms_px: must be a finite number,
//   got '.nan'
// Plain C++ over Eigen: no runtime, no messages.
#pragma once

#include <tessera/camera_network/camera_constraint_builder.hpp>
#include <tessera/geometry/floor_camera_calibration.hpp>

#include <Eigen/Core>

#include <cstdint>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

namespace tessera::camera_network {

class CameraCalibrationFileError : public std::runtime_error {
 public:
  /// what() = "FILE[:LINE]: FIELD: PROBLEM" (FIELD omitted when empty); line 0 = unknown.
  CameraCalibrationFileError(const std::filesystem::path& file, int line, const std::string& field,
                             const std::string& problem);
  const std::filesystem::path& file() const { return file_; }
  int line() const { return line_; }
  /// E.g. "cameras[1] (camera 3): rms_px", "cameras", or "" for the file as a whole.
  const std::string& field() const { return field_; }

 private:
  std::filesystem::path file_;
  int line_ = 0;
  std::string field_;
};

/// One camera's calibration as stored in the file: the same record (and validity check,
/// tessera::floorCameraCalibrationProblem) that saved SLAM states hold.
using CameraCalibrationRecord = tessera::FloorCameraCalibration;

/// The record of a calibration the builder holds.
CameraCalibrationRecord calibrationRecord(const CameraCalibration& calibration);

/// Writes `records` to `path` (its folder must exist), by increasing camera id. Throws
/// CameraCalibrationFileError for an invalid record, a camera id given twice, or a failed write.
void writeCameraCalibrations(const std::filesystem::path& path,
                             const std::vector<CameraCalibrationRecord>& records);

/// Reads a file written by writeCameraCalibrations(), in file order. Throws
/// CameraCalibrationFileError.
std::vector<CameraCalibrationRecord> readCameraCalibrations(const std::filesystem::path& path);

}  // namespace tessera::camera_network
