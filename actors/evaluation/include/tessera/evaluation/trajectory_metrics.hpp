// Accuracy metrics for estimated trajectories and landmark maps (`tessera eval`).
//
// - ATE (absolute trajectory error, TUM RGB-D benchmark conventions): estimate and reference
//   poses are associated by time stamp (closest pairs first, each pose used once, |Δt| ≤
//   max_difference_s), the estimate positions are aligned onto the reference positions by a
//   least-squares rigid motion (Umeyama 1991; optionally with scale), and the remaining position
//   differences are the errors [m].
// - RPE (relative pose error, TUM conventions with a fixed delta): for estimate pose pairs (i, j)
//   `delta` apart (seconds by default, or frames), E = (G_i⁻¹ G_j)⁻¹ (P_i⁻¹ P_j) where G are the
//   reference poses with the nearest stamps (within twice the median reference interval, else the
//   pair is dropped). Errors are |translation(E)| [m] and angle(E) [deg]. No alignment needed.
// - Relations (Kümmerle et al. 2009, "On measuring the accuracy of SLAM algorithms"): for each
//   true relative pose δ between times t1 and t2, e = δ⁻¹ ⊕ (x(t1)⁻¹ ⊕ x(t2)) with x(t) the
//   estimate interpolated on SE(2) at t. Reported, as in the paper's tables: mean ± std of the
//   absolute translational error |e_xy| [m], of its square [m²], of the absolute rotational error
//   |e_θ| [deg] and of its square [deg²]. (|e| is the same for e⁻¹, so the order of the
//   composition does not matter; the frame convention of δ does.) The result also keeps every
//   relation's error, for analysis over time (binRelationErrors), and, with max_speed set,
//   separate statistics of the relations whose true displacement fits their time stamps (a log
//   with rebuilt stamps holds relations no robot could have driven: their error is a floor that
//   no trajectory can go under).
// - Heading drift (odometry): estimate and reference associated by time as for ATE, no
//   alignment; the heading error e_k = (θ_est,k − θ_est,0) − (θ_ref,k − θ_ref,0) of every pair
//   relative to the first, unwrapped (accumulated from wrapped per-pair increments, so a drift
//   beyond ±π is not folded back). Reported: the final |e|, the RMS and the max of |e| [deg].
//   Planar: headings are the yaws of the poses.
// - Landmarks: estimate and reference landmarks associated by id, rigid 2D alignment (Umeyama),
//   position errors [m].
//
// Planar (SE(2)) or spatial (SE(3)) mode: Dimension::kAuto is planar when every pose of both
// trajectories has z = 0 and a rotation about z only (how Tessera writes 2D poses); planar mode
// aligns with a rotation about z plus an xy translation and measures errors in the xy plane.
//
// Standard deviations are sample standard deviations (divided by n − 1). Inputs need not be
// sorted by time. Functions throw MetricError when nothing can be compared.
#pragma once

#include <tessera/evaluation/landmark_io.hpp>
#include <tessera/geometry/pose2.hpp>
#include <tessera/mapping/trajectory_io.hpp>

#include <Eigen/Core>

#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <utility>
#include <vector>

namespace tessera::evaluation {

class MetricError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Summary of a set of errors.
struct ErrorStats {
  std::size_t count = 0;
  double rmse = 0, mean = 0, std = 0, median = 0, min = 0, max = 0;
};
/// Statistics of `values` (all zero when empty; std = 0 for a single value).
ErrorStats summarize(std::vector<double> values);

enum class Dimension { kAuto, kPlanar, kSpatial };

/// True when every pose has |z| ≤ tol and a rotation about z only (|qx|, |qy| ≤ tol).
bool isPlanar(const std::vector<mapping::TumPose>& poses, double tol = 1e-6);

/// A similarity transform p ↦ scale · R p + t (scale = 1 unless asked for). In planar mode R is
/// a rotation about z and t_z = 0.
struct Alignment {
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();  ///< [m]
  double scale = 1.0;
  Eigen::Vector3d apply(const Eigen::Vector3d& p) const {
    return scale * (rotation * p) + translation;
  }
  /// The inverse: a reference-frame point in the estimate's frame (e.g. true walls moved into a
  /// SLAM map's frame).
  Eigen::Vector3d unapply(const Eigen::Vector3d& p) const {
    return rotation.transpose() * (p - translation) / scale;
  }
};

/// Least-squares alignment of the columns of `from` onto those of `to` (same count). Planar: z
/// is ignored. One point gives a translation; with_scale needs points that do not coincide.
Alignment alignPoints(const Eigen::Matrix3Xd& from, const Eigen::Matrix3Xd& to, bool planar,
                      bool with_scale);

/// Index into sorted, non-empty `stamps` of the stamp nearest to t (the earlier one on a tie).
std::size_t nearestIndex(const std::vector<std::int64_t>& stamps, std::int64_t t);

struct AssociationOptions {
  double max_difference_s = 0.02;  ///< [s] largest stamp difference of a pair (TUM default)
  double offset_s = 0.0;           ///< [s] added to the estimate stamps before comparing
};
/// (estimate index, reference index) pairs, sorted by estimate stamp.
std::vector<std::pair<std::size_t, std::size_t>> associateByTime(
    const std::vector<mapping::TumPose>& estimate, const std::vector<mapping::TumPose>& reference,
    const AssociationOptions& options);

struct AteOptions {
  AssociationOptions association;
  Dimension dimension = Dimension::kAuto;
  bool scale = false;  ///< Sim(3)/Sim(2) alignment, for monocular estimates
};
struct AteResult {
  std::size_t estimate_poses = 0, reference_poses = 0, pairs = 0;
  bool planar = false;
  Alignment alignment;         ///< maps estimate positions onto the reference
  ErrorStats translation;      ///< [m]
  std::vector<double> errors;  ///< [m] per pair, in estimate-stamp order
};
AteResult computeAte(const std::vector<mapping::TumPose>& estimate,
                     const std::vector<mapping::TumPose>& reference,
                     const AteOptions& options = {});

/// ATE of several trajectories in one frame (several robots in a merged map): ONE rigid
/// alignment of all their pose pairs onto their references (the references share a frame, e.g.
/// the simulator's world), then each trajectory's errors under it; beside each, its ATE aligned
/// on its own (what it would score alone). Throws MetricError when a trajectory has no pairs.
struct JointAteResult {
  bool planar = false;
  Alignment alignment;            ///< the one alignment
  std::vector<AteResult> alone;   ///< each aligned on its own
  std::vector<ErrorStats> joint;  ///< each under the one alignment [m]
};
JointAteResult computeJointAte(
    const std::vector<std::pair<std::vector<mapping::TumPose>, std::vector<mapping::TumPose>>>&
        trajectories,
    const AteOptions& options = {});

struct HeadingDriftResult {
  std::size_t estimate_poses = 0, reference_poses = 0, pairs = 0;
  double final_deg = 0;         ///< |e| at the last pair [deg]
  double final_signed_deg = 0;  ///< e at the last pair [deg]
  double duration_s = 0;        ///< reference time from the first to the last pair [s]
  ErrorStats error_deg;         ///< |e| over all pairs [deg]
};
HeadingDriftResult computeHeadingDrift(const std::vector<mapping::TumPose>& estimate,
                                       const std::vector<mapping::TumPose>& reference,
                                       const AssociationOptions& options = {});

enum class DeltaUnit { kSeconds, kFrames };
struct RpeOptions {
  double delta = 1.0;  ///< pair spacing: seconds, or a whole number of frames
  DeltaUnit unit = DeltaUnit::kSeconds;
  double offset_s = 0.0;  ///< [s] added to the estimate stamps
  Dimension dimension = Dimension::kAuto;
};
struct RpeResult {
  std::size_t estimate_poses = 0, reference_poses = 0, pairs = 0;
  bool planar = false;
  ErrorStats translation;   ///< [m]
  ErrorStats rotation_deg;  ///< [deg]
};
RpeResult computeRpe(const std::vector<mapping::TumPose>& estimate,
                     const std::vector<mapping::TumPose>& reference,
                     const RpeOptions& options = {});

/// A planar trajectory that can be sampled at any time inside it.
class PlanarTrajectory {
 public:
  /// Projects the poses to SE(2) and sorts them by stamp (stable: equal stamps keep file order;
  /// a time between two stamps uses the last pose of the earlier stamp and the first of the
  /// later one, a time equal to a repeated stamp the last pose with it).
  explicit PlanarTrajectory(const std::vector<mapping::TumPose>& poses);

  enum class Lookup { kOk, kOutside, kInGap };
  /// The pose at `stamp_ns`, interpolated between the two poses around it (position linearly,
  /// heading along the shorter arc). kOutside before the first or after the last pose; kInGap
  /// when the two poses around it are more than max_gap_ns apart (max_gap_ns ≤ 0: no limit).
  Lookup at(std::int64_t stamp_ns, std::int64_t max_gap_ns, Pose2& pose) const;

  std::size_t size() const { return stamps_.size(); }

 private:
  std::vector<std::int64_t> stamps_;
  std::vector<Pose2> poses_;
};

/// A true relative pose: the pose at t2 in the frame of the pose at t1.
struct PoseRelation {
  std::int64_t t1_ns = 0, t2_ns = 0;
  Pose2 delta;
};
struct RelationsOptions {
  /// [s] a relation time between two trajectory poses further apart than this is not matched
  /// (interpolating across a hole would invent the pose). ≤ 0: no limit. 30 s lets through
  /// the sparse key-frame trajectories SLAM front ends write (GMapping's Intel run: 14 s gaps
  /// while the robot stands still) and stops lost-tracking holes.
  double max_gap_s = 30.0;
  /// [s] added to the trajectory stamps, for trajectories in another time base.
  double time_offset_s = 0.0;
  /// [m/s] a relation whose true displacement |(dx, dy)| / |t2 − t1| exceeds this is
  /// inconsistent with its time stamps (no robot of the log drives that fast: its stamps are
  /// wrong) and is left out of the `consistent_*` statistics. It stays in the headline figures.
  /// 0: off (every relation is consistent). Negative or not a number: MetricError.
  double max_speed = 0.0;
};
/// One relation's outcome, in the order of the relations set.
struct RelationError {
  std::int64_t t1_ns = 0, t2_ns = 0;  ///< the relation's times (relations' time base)
  bool matched = false;               ///< evaluated; else the errors below are 0
  bool consistent = true;             ///< speed ≤ max_speed, or max_speed off
  double translation = 0;             ///< |e_xy| [m]
  double rotation_rad = 0;            ///< |e_θ| [rad]
  double speed = 0;  ///< [m/s] |(dx, dy)| / |t2 − t1| of the true relation (∞ if t1 = t2)
};
struct RelationsResult {
  std::size_t relations = 0;        ///< in the relations set
  std::size_t matched = 0;          ///< evaluated
  std::size_t outside = 0;          ///< not matched: a time before/after the trajectory
  std::size_t in_gap = 0;           ///< not matched: a time inside a gap longer than max_gap_s
  ErrorStats translation;           ///< |e_xy| [m], over all matched relations
  ErrorStats translation_squared;   ///< |e_xy|² [m²]
  ErrorStats rotation_deg;          ///< |e_θ| [deg]
  ErrorStats rotation_squared_deg;  ///< |e_θ|² [deg²]
  /// Matched relations faster than options.max_speed (0 when it is off).
  std::size_t inconsistent = 0;
  /// The same four figures over the matched relations that are consistent with their time
  /// stamps (count = matched − inconsistent; equal to the headline when max_speed is off).
  ErrorStats consistent_translation;           ///< [m]
  ErrorStats consistent_translation_squared;   ///< [m²]
  ErrorStats consistent_rotation_deg;          ///< [deg]
  ErrorStats consistent_rotation_squared_deg;  ///< [deg²]
  std::vector<RelationError> errors;           ///< every relation, matched or not, in input order
};
RelationsResult computeRelationsError(const std::vector<mapping::TumPose>& trajectory,
                                      const std::vector<PoseRelation>& relations,
                                      const RelationsOptions& options = {});

/// The mean error of the matched relations whose t1 falls in [start_s, start_s + width).
struct RelationsBin {
  double start_s = 0;            ///< [s] since the earliest t1 of all relations (matched or not)
  std::size_t count = 0;         ///< matched relations in the bin (0: the means are 0)
  double translation_mean = 0;   ///< mean |e_xy| [m]
  double rotation_mean_deg = 0;  ///< mean |e_θ| [deg]
};
/// Bins `errors` (RelationsResult::errors) by t1, measured from the earliest t1 among them, into
/// consecutive bins of width_s seconds from 0 up to the bin holding the latest t1; empty bins are
/// kept (count 0) so that bins line up across trajectories scored on the same relations. Throws
/// MetricError for a width that is not a positive finite number, for more than 1 000 000 bins,
/// and returns no bins for no errors.
std::vector<RelationsBin> binRelationErrors(const std::vector<RelationError>& errors,
                                            double width_s);

struct LandmarkResult {
  std::size_t estimate_landmarks = 0, reference_landmarks = 0, pairs = 0;
  Alignment alignment;  ///< maps estimate positions onto the reference (planar)
  ErrorStats error;     ///< [m]
};
LandmarkResult computeLandmarkError(const std::vector<Landmark>& estimate,
                                    const std::vector<Landmark>& reference, bool scale = false);

}  // namespace tessera::evaluation
