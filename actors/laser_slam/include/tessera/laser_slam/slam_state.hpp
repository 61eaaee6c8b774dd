// SlamState: what the two-level laser SLAM built, kept on disk so that a later run reloads the
// map without running SLAM again: the submaps (occupancy grids, each in its own frame, with the
// submap frame's optimised pose in the map frame), the submap pose graph's constraints, and the
// environment cameras' calibrations, each in the submap it was made in.
//
// On disk (format "tessera-slam-state", version 2; docs/architecture.md#saved-slam-state): a
// directory holding state.yaml (frame id, every submap's id, origin, grid geometry, file and
// checksum; every constraint; every camera calibration) and one raw cell file per submap
// (submap_<id>.cells: width*height int8 ROS cell values, row-major from grid row 0), so a save ->
// load round trip is exact (numbers are written in their shortest round-trip form). Version 1
// (no cameras) still loads, with no cameras; a state is always saved as version 2.
//
// Frames and units: `origin` = pose of the submap frame in the map frame `frame_id`; the grid's
// own `origin` = outer corner of cell (0,0) in the submap frame; a constraint from -> to = pose
// of `to`'s frame in `from`'s frame with its information matrix over (x [m], y [m], θ [rad]) in
// `from`'s frame; a camera's homography maps floor points [m] in its submap's frame to pixels
// [px]. Metres, radians. Values own their data; plain C++, no runtime or messages.
//
// Errors: loadSlamState() and saveSlamState() throw SlamStateError naming the file (and line)
// and the field or value at fault: a missing directory or file, a wrong `format`, a version
// other than 1 or 2, malformed or non-finite fields, duplicate ids, cell files of the wrong size
// or checksum, cameras naming an unsaved submap or with a homography that is not 9 finite
// numbers or is singular.
#pragma once

#include <tessera/geometry/floor_camera_calibration.hpp>
#include <tessera/geometry/pose2.hpp>
#include <tessera/grid/occupancy_map.hpp>

#include <Eigen/Core>

#include <cstdint>
#include <filesystem>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace tessera::laser_slam {

class SlamStateError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct SavedSubmap {
  int id = 0;                        ///< >= 0, unique in a state
  tessera::Pose2 origin;             ///< submap frame in the map frame (the optimised pose)
  tessera::grid::OccupancyMap grid;  ///< in the submap frame; cells -1 (unknown) or 0..100
  bool finished = true;              ///< false: a snapshot of a submap still being built
};

struct SavedConstraint {
  int from = 0;
  int to = 0;
  tessera::Pose2 relative;  ///< pose of `to`'s frame in `from`'s frame
  Eigen::Matrix3d information = Eigen::Matrix3d::Identity();  ///< symmetric, finite
  bool revisit = false;  ///< false: the hand-over from `from` to the new submap `to`
};

/// An environment camera's floor-plane calibration (docs/algorithms.md#camera-network-calibration):
/// the record camera calibration files hold too, checked by tessera::floorCameraCalibrationProblem;
/// a saved one must also name a saved submap.
using SavedCamera = tessera::FloorCameraCalibration;

struct SlamState {
  static constexpr int kFormatVersion = 2;        ///< the version saveSlamState() writes
  static constexpr int kOldestFormatVersion = 1;  ///< the oldest loadSlamState() reads
  static constexpr const char* kFormatName = "tessera-slam-state";

  /// The version it was loaded from (kFormatVersion for a new state); saving always writes
  /// kFormatVersion and accepts any version this build reads.
  int format_version = kFormatVersion;
  std::string frame_id = "map";
  std::vector<SavedSubmap> submaps;          ///< any order; written by increasing id
  std::vector<SavedConstraint> constraints;  ///< each names two saved submaps
  std::vector<SavedCamera> cameras;          ///< each names a saved submap; written by id
};

/// Writes `state` into directory `dir` (created if needed): the cell files first, state.yaml
/// last, so an interrupted save leaves no state.yaml that names missing files. Checks the whole
/// state as loadSlamState() would before writing anything. Throws SlamStateError.
void saveSlamState(const SlamState& state, const std::filesystem::path& dir);

/// Writes a state one submap at a time, for a caller that keeps its submaps packed
/// (MapAssembler) and should not hold them all unpacked at once: addSubmap() checks a submap and
/// writes its cell file at once, so the grid can be freed right after; addConstraint() and
/// addCamera() need the submaps they name added before; finish() writes state.yaml, last. The
/// files, checks and error texts are saveSlamState()'s (which uses this writer); a check that
/// fails throws SlamStateError and leaves no new state.yaml. Holds only each submap's header.
class SlamStateWriter {
 public:
  /// Checks `format_version` and `frame_id`; the directory is created at the first write.
  SlamStateWriter(std::filesystem::path dir, std::string frame_id,
                  int format_version = SlamState::kFormatVersion);
  ~SlamStateWriter();
  SlamStateWriter(const SlamStateWriter&) = delete;
  SlamStateWriter& operator=(const SlamStateWriter&) = delete;

  void addSubmap(const SavedSubmap& submap);
  void addConstraint(const SavedConstraint& constraint);
  void addCamera(const SavedCamera& camera);
  /// Writes state.yaml (submaps and cameras by increasing id, constraints as added); once.
  void finish();

  std::size_t submaps() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Reads a state written by saveSlamState() (version 1 or 2); submaps and cameras by increasing
/// id. Throws SlamStateError.
SlamState loadSlamState(const std::filesystem::path& dir);

/// The global map of a state: every submap drawn at its origin (MapAssembler, same rule as the
/// map_assembler actor); resolution [m/cell], 0 = the finest submap's. Empty when no submaps.
tessera::grid::OccupancyMap assembleSlamState(const SlamState& state, double resolution = 0.0);

}  // namespace tessera::laser_slam
