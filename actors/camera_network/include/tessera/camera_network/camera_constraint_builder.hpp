// CameraConstraintBuilder: the camera network's part of the two-level laser SLAM
// (docs/algorithms.md#camera-network-calibration). Fed the cameras' enter/leave events, their
// marker sightings paired with the SLAM's robot pose at the same time, and the submap hand-overs,
// it calibrates each camera from the robot's motion and turns later visits into revisit
// constraints between submaps.
//
// Frames. Robot poses come in the submap builder's chained map frame (the first submap's frame,
// later submaps placed by chaining hand-overs); hand-overs say where each submap starts in it.
// A pose in submap s is origin_s⁻¹ ⊕ chained pose, consistent across a hand-over because the
// chain is. The marker sits at `marker` in base_link.
//
// A camera's life:
//  * Uncalibrated: every visit collects (marker position, pixel) pairs; at the end of the visit
//    (leave, or finish()) they are converted into the submap current then (with a camera trigger,
//    the one started when the robot entered) and calibrated (estimateFloorHomography). Accepted:
//    the camera is calibrated in that submap. Refused: the reason is reported and the next visit
//    tries again.
//  * Calibrated in submap j: a visit while the robot is in another submap i gives, at its end,
//    the marker's positions in j (camera localisation through the homography) beside the SLAM's
//    in i; their rigid fit (fitMapTransform) is the revisit constraint i -> j (pose of j's origin
//    in i), its covariance that of the fit plus the calibration's, propagated to first order, plus
//    the SLAM's one rigid error of the whole visit in i (slam_anchor_std_*). A
//    visit while still in j checks the calibration: its positions against the SLAM's.
//  * Stale: a visit whose camera positions disagree with the SLAM (fit RMS above
//    revisit.max_rms_m, i.e. the camera moved or its calibration was poor) gives no constraint;
//    `stale_visits` such visits in a row drop the calibration, and that visit's pairs calibrate
//    it again in the current submap.
// Smoothed poses (smoothed_poses, the default): the SLAM's online pose of a sighting is replaced by
// its smoothed pose from the finished submap's trajectory (addTrajectory; the submap builder's
// final best particle, which is more accurate than the online estimate), so a visit is held
// until every submap its sightings fall in has finished (or finish()). A stamp between two
// trajectories keeps its online pose.
// Unanchored submaps (addSubmap with anchored = false: the SLAM lost the map and started a
// submap it could not place, e.g. a kidnapped robot): from that submap on, the first visit of a
// calibrated camera is the relocalisation. It is processed at its end with the online poses
// instead of waiting for smoothed ones, so the graph places the robot again within seconds; its
// revisit (CameraOutput::relocalisation) anchors the chain and later visits are held as usual.
// That revisit is provisional: its covariance is scaled up by relocalisation_covariance_scale,
// and the same visit is also held and, once smoothed, gives the revisit again
// (CameraOutput::refines_relocalisation), which outweighs the provisional one where the graph
// fuses the two.
// Odometry shape (odometry_shape, the default): where the sightings carry the odometry's pose at
// their stamp, a visit's path is the odometry's, placed on the SLAM's poses by the rigid
// transform that fits it to them best (least squares over the robot positions). Over the tens of
// seconds of a visit wheel odometry keeps the path's shape far better than the SLAM, whose
// scan matching wanders by centimetres (docs/algorithms.md#camera-network-calibration); the SLAM
// still says where the path is in its submap. Sightings without odometry keep the SLAM's pose,
// and visits longer than odometry_shape_max_s (where odometry drifts) are not reshaped.
// Visit path (visit_path, the default): a calibration visit shaped by the odometry is first
// calibrated as it is; then its path and the homography are refined together
// (refineVisitPath: the wheels' random error bends the path by about a pixel over a loop) and
// the camera is calibrated again on the corrected path, placed on the SLAM's poses of the visit;
// it is kept if that calibration is accepted. Revisits keep the odometry's path.
// Nothing throws for bad data: non-finite sightings and sightings of unknown cameras are counted
// and ignored.
#pragma once

#include <tessera/camera_network/camera_localization.hpp>
#include <tessera/camera_network/floor_homography.hpp>
#include <tessera/camera_network/visit_path.hpp>
#include <tessera/config/config_check.hpp>
#include <tessera/geometry/pose2.hpp>

#include <Eigen/Core>

#include <cstdint>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace tessera::camera_network {

struct CameraConstraintBuilderOptions {
  /// The SLAM places each calibration visit in its submap with one error of a few centimetres
  /// (its wander, docs/algorithms.md#camera-network-calibration), which no residual shows: it is
  /// the calibration's anchor uncertainty.
  FloorHomographyOptions calibration = [] {
    FloorHomographyOptions o;
    o.anchor_std_m = 0.02;
    o.anchor_std_rad = 0.007;
    return o;
  }();
  MapTransformOptions revisit;
  std::vector<double> marker = {0, 0};  ///< marker in base_link [x m, y m]
  int image_width_px = 640;
  int image_height_px = 480;
  /// Position std [m] of the SLAM's robot pose within its submap, per axis, used in the revisit
  /// fit (a fresh submap's particle spread is a few cm).
  double slam_position_std_m = 0.03;
  /// The SLAM places a revisit's whole path in submap i with one error, as it does a calibration
  /// visit's in j (the calibration's anchor): a shift [m] per axis and a turn [rad] about the
  /// path's centroid, shared by every sighting, so it does not average down. Added to the
  /// revisit's covariance. Without it the revisits' NEES against the truth was 4-7 over the
  /// camera floor's route (docs/algorithms.md#camera-network-calibration).
  double slam_anchor_std_m = 0.02;
  double slam_anchor_std_rad = 0.007;
  bool smoothed_poses = true;
  int stale_visits = 2;
  int max_visit_sightings = 3000;  ///< a visit keeps at most this many (later ones are dropped)
  bool odometry_shape = true;
  double odometry_shape_max_s = 120.0;  ///< longer visits keep the SLAM's poses
  /// An odometry-shaped calibration visit's path is refined with the camera's pixels first.
  VisitPathOptions visit_path;
  /// The relocalisation's revisit (online poses) has its covariance multiplied by this (>= 1).
  double relocalisation_covariance_scale = 100.0;

  template <class V>
  void visit(V& v) {
    v("calibration", calibration, "floor-plane homography estimation and its refusals");
    v("revisit", revisit, "revisit constraints from a calibrated camera");
    v("marker", marker, "marker position in base_link [x m, y m]");
    v("image_width_px", image_width_px, "camera image width [px] (coverage)");
    v("image_height_px", image_height_px, "camera image height [px]");
    v("slam_position_std_m", slam_position_std_m,
      "std of the SLAM's robot position in its submap, per axis, in revisit fits [m]");
    v("slam_anchor_std_m", slam_anchor_std_m,
      "std of the shift, per axis, shared by a revisit's whole path in the SLAM's submap [m]");
    v("slam_anchor_std_rad", slam_anchor_std_rad,
      "std of the turn about its centroid shared by a revisit's whole path [rad]");
    v("smoothed_poses", smoothed_poses,
      "hold each visit until its submaps have finished and use their smoothed trajectories "
      "instead of the online poses");
    v("stale_visits", stale_visits,
      "drop a calibration after this many visits in a row disagree with the SLAM");
    v("max_visit_sightings", max_visit_sightings, "sightings kept per visit");
    v("odometry_shape", odometry_shape,
      "use each visit's odometry path, rigidly placed on the SLAM's poses, instead of the SLAM's "
      "path (sightings that carry odometry)");
    v("odometry_shape_max_s", odometry_shape_max_s,
      "visits longer than this [s] keep the SLAM's poses (odometry drifts)");
    v("visit_path", visit_path,
      "refine an odometry-shaped calibration visit's path with the camera's pixels");
    v("relocalisation_covariance_scale", relocalisation_covariance_scale,
      "multiply the covariance of a relocalisation's revisit (online poses, provisional) by this; "
      "the same visit refit on smoothed poses follows and outweighs it (smoothed_poses)");
  }
  ConfigCheck check() const;
};

/// A sighting of the marker by one camera at one time, with the SLAM's robot pose then.
struct CameraSighting {
  std::int64_t stamp_ns = 0;
  int camera = 0;
  Eigen::Vector2d pixel = Eigen::Vector2d::Zero();  ///< [px]
  double pixel_std = 1.0;                           ///< [px]
  Pose2 robot;                                      ///< chained map frame
  /// The odometry's pose at the same stamp (its own frame), when known (odometry_shape).
  std::optional<Pose2> odometry;
};

struct CameraCalibration {
  int camera = 0;
  std::uint32_t submap = 0;  ///< the frame of the floor points
  std::int64_t stamp_ns = 0;
  FloorHomography homography;
};

/// What one event produced.
struct CameraOutput {
  enum class Kind { kCalibrated, kCalibrationRefused, kRevisit, kRevisitRefused, kChecked };
  Kind kind = Kind::kCalibrated;
  int camera = 0;
  std::int64_t stamp_ns = 0;
  std::string reason;                            ///< refusals
  std::optional<CameraCalibration> calibration;  ///< kCalibrated
  // kRevisit: pose of submap `to`'s origin in submap `from`'s frame, covariance in from's frame.
  std::uint32_t from = 0, to = 0;
  Pose2 relative;
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  double rms_m = 0;  ///< kRevisit / kRevisitRefused / kChecked: camera vs SLAM positions
  int sightings = 0;
  /// kRevisit: the robot's pose in submap `to` at the last sighting (camera localisation).
  Pose2 robot_in_to;
  /// kRevisit / kRevisitRefused: the first visit of a calibrated camera after an unanchored
  /// submap, processed with online poses (covariance scaled by relocalisation_covariance_scale).
  bool relocalisation = false;
  /// kRevisit / kRevisitRefused: that visit again, on smoothed poses (smoothed_poses).
  bool refines_relocalisation = false;
};

class CameraConstraintBuilder {
 public:
  /// Throws std::invalid_argument naming the bad option.
  explicit CameraConstraintBuilder(CameraConstraintBuilderOptions options);

  /// Submap `id` starts at `origin` (chained frame). Submap 0 starts at the identity unless
  /// told otherwise. `anchored` false: the SLAM could not place it (lost); see above. False
  /// (ignored) for a non-finite origin.
  bool addSubmap(std::uint32_t id, const Pose2& origin, bool anchored = true);
  /// The first unanchored submap not yet placed by a relocalisation, if any.
  std::optional<std::uint32_t> unanchoredSince() const { return unanchored_since_; }
  /// The smoothed robot poses [stamp ns, pose in the submap's frame] of finished submap `id`,
  /// by increasing stamp; releases the visits they complete (smoothed_poses). Non-finite poses
  /// are skipped.
  std::vector<CameraOutput> addTrajectory(std::uint32_t id,
                                          const std::vector<std::pair<std::int64_t, Pose2>>& poses);
  /// The robot entered / left camera `camera`'s view. Leaving ends the visit.
  std::vector<CameraOutput> enter(int camera, std::int64_t stamp_ns);
  std::vector<CameraOutput> leave(int camera, std::int64_t stamp_ns);
  /// A sighting during a visit (one without an enter starts a visit). False when ignored
  /// (non-finite, or the visit is full).
  bool add(const CameraSighting& sighting);
  /// Ends every open visit and releases every held one (end of the run).
  std::vector<CameraOutput> finish(std::int64_t stamp_ns);

  /// Calibrations in force, by camera.
  const std::map<int, CameraCalibration>& calibrations() const { return calibrations_; }
  std::uint32_t currentSubmap() const { return current_; }
  std::uint64_t ignoredSightings() const { return ignored_; }
  /// Visits whose path was the odometry's (odometry_shape).
  std::uint64_t odometryShapedVisits() const { return odometry_shaped_; }
  /// Calibrations made on a path refined with the camera's pixels (visit_path).
  std::uint64_t refinedVisitPaths() const { return refined_paths_; }
  /// Visits ended but held for their submaps' smoothed trajectories.
  std::size_t heldVisits() const { return held_.size(); }

 private:
  struct Visit {
    std::vector<CameraSighting> sightings;
  };
  struct HeldVisit {
    int camera = 0;
    std::uint32_t submap = 0;  // current when the visit ended
    std::int64_t stamp_ns = 0;
    std::vector<CameraSighting> sightings;
    bool relocalisation = false;
    bool refines_relocalisation = false;
  };
  std::vector<CameraOutput> endVisit(int camera, std::int64_t stamp_ns);
  std::vector<CameraOutput> release(bool all);
  std::vector<CameraOutput> process(HeldVisit visit);
  /// `slam`: set when every sighting's pose is the odometry's, the SLAM's poses they replaced
  /// (visit_path refines the odometry's path and places it on them).
  std::optional<CameraOutput> calibrate(int camera, const std::vector<CameraSighting>& s,
                                        std::uint32_t submap, std::int64_t stamp_ns,
                                        const std::vector<Pose2>* slam);
  /// The chained pose at `stamp` from the smoothed trajectories (the first to end at or after it,
  /// if it has begun by then), or `online` when none holds it.
  Pose2 smoothed(std::int64_t stamp, const Pose2& online) const;
  /// A chained-frame pose in submap `submap`'s frame (origin_s⁻¹ ⊕ pose).
  Pose2 poseIn(std::uint32_t submap, const Pose2& chained) const;
  Eigen::Vector2d markerIn(std::uint32_t submap, const Pose2& chained_robot) const;
  /// odometry_shape: replaces the robot poses of the sightings that carry odometry by the
  /// odometry's, rigidly placed on the SLAM's. False when the visit is left as it is.
  bool placeOdometryShape(std::vector<CameraSighting>& sightings) const;

  CameraConstraintBuilderOptions options_;
  Eigen::Vector2d marker_;
  std::map<std::uint32_t, Pose2> origins_;
  std::uint32_t current_ = 0;
  std::map<int, Visit> visits_;
  std::vector<HeldVisit> held_;
  std::map<std::uint32_t, std::vector<std::pair<std::int64_t, Pose2>>> trajectories_;
  /// Finished submaps by the last stamp of their trajectory: the one holding a stamp is found by
  /// one lookup (submaps follow each other in time).
  std::map<std::int64_t, std::uint32_t> trajectory_ends_;
  std::int64_t smoothed_until_ = std::numeric_limits<std::int64_t>::min();
  std::map<int, CameraCalibration> calibrations_;
  std::map<int, int> strikes_;
  std::uint64_t ignored_ = 0;
  std::uint64_t odometry_shaped_ = 0;
  std::uint64_t refined_paths_ = 0;
  std::optional<std::uint32_t> unanchored_since_;
};

}  // namespace tessera::camera_network
