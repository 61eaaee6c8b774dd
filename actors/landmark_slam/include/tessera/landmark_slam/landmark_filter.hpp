// Point-landmark SLAM filters (docs/algorithms.md#landmark-slam): the common part of EkfSlam (joint
// state) and RbUkfSlam (the seed 004 Rao-Blackwellised filter). Plain C++ over Eigen, no runtime
// types.
//
// One cycle: predict(control) moves the pose; update(observations) runs observe (validation and
// data association against the state before this scan), update (one sequential correction per
// associated observation) and augment (new landmarks from range-bearing) — the seed 004 steps.
//
// Frames and units: pose (x, y, theta) of base_link in the map frame [m, m, rad]; landmarks
// (x, y) in the map frame [m]; observations (range [m], bearing [rad]) from the sensor mounted
// at `mount` in base_link (models in tessera/landmark_slam/landmark_models.hpp). The map frame is
// the filter's start frame (initial_pose, default the origin).
//
// Data association:
//  - kKnownIds: the observation's id names the landmark; an unseen id adds a landmark. An
//    observation without an id (id < 0) is rejected (unknown_id). A known-id observation whose
//    squared Mahalanobis distance exceeds outlier_gate is rejected (gate); a second sighting of
//    one id in one scan is rejected (duplicate).
//  - kNearestNeighbour: ids are ignored; each observation goes to the landmark with the smallest
//    squared Mahalanobis distance d² (innovation linearised at the current estimate). d² <
//    association_gate: matched, unless a second landmark is also inside the gate with
//    d²_2 - d²_1 < ambiguity_margin, then the observation is dropped (ambiguous): a wrong
//    association corrupts the filter for good, a dropped sighting only loses information.
//    d²_1 > new_landmark_gate (or an empty map): a new landmark. In between: dropped
//    (between_gates), neither clearly old nor clearly new. Two observations matched to one
//    landmark in a scan: the closer one keeps it, the other is dropped (duplicate). New
//    landmarks get ids 0, 1, 2, ... in order of creation.
// Always: non-finite values (non_finite) and ranges <= 0 (negative_range) are rejected; every
// rejection is counted by reason and never throws.
#pragma once

#include <tessera/geometry/pose2.hpp>
#include <tessera/landmark_slam/landmark_models.hpp>
#include <tessera/landmark_slam/unscented.hpp>

#include <Eigen/Core>

#include <array>
#include <cstddef>
#include <cstdint>
#include <numbers>
#include <span>
#include <unordered_map>
#include <utility>
#include <vector>

namespace tessera::landmark_slam {

/// One degree [rad], for defaults written in degrees.
inline constexpr double kDegree = std::numbers::pi / 180;

/// Which filter: the EKF-SLAM baseline (EkfSlam) or the seed 004 filter (RbUkfSlam).
enum class FilterType { kEkf, kRbEkf };
constexpr std::array<std::pair<const char*, FilterType>, 2> optionNames(FilterType) {
  return {{{"ekf", FilterType::kEkf}, {"rbekf", FilterType::kRbEkf}}};
}

enum class Association { kKnownIds, kNearestNeighbour };
constexpr std::array<std::pair<const char*, Association>, 2> optionNames(Association) {
  return {{{"known", Association::kKnownIds}, {"nearest", Association::kNearestNeighbour}}};
}

struct LandmarkSlamOptions {
  Association association = Association::kKnownIds;
  /// Observation noise used when an observation carries no std (or use_observation_std is off).
  double range_std = 0.1;            ///< [m]
  double bearing_std = 1 * kDegree;  ///< [rad]
  bool use_observation_std = true;   ///< prefer the stds an observation carries
  /// Control noise (1-sigma of the control as applied over one step).
  double sigma_speed = 0.3;              ///< [m/s]
  double sigma_steer = 3 * kDegree;      ///< [rad] car-like steering angle
  double sigma_turn_rate = 3 * kDegree;  ///< [rad/s] differential-drive turn rate
  /// Gates on squared Mahalanobis distances (2 dof): chi2(0.9999) = 18.4, chi2(0.99) = 9.21.
  double outlier_gate = 18.420680743952367;       ///< known ids; 0 = accept every known id
  double association_gate = 9.210340371976182;    ///< nearest neighbour: match below this
  double new_landmark_gate = 18.420680743952367;  ///< nearest neighbour: new landmark above
  double ambiguity_margin = 4.0;  ///< second candidate this close in d² -> ambiguous
  /// Start pose [x m, y m, theta rad] in the map frame (map frame = the start frame by default).
  std::vector<double> initial_pose = {0, 0, 0};
  /// Initial pose 1-sigma [m, m, rad]; 0 = exactly known (the UKF handles a singular cov).
  std::vector<double> initial_std = {0, 0, 0};
  tessera::landmark_slam::UnscentedParams unscented;  ///< RbUkfSlam only
  /// Throws std::invalid_argument naming the first bad field (its key in visit()).
  void validate() const;
  /// initial_pose (theta wrapped) and the diagonal covariance from initial_std; valid options.
  tessera::Pose2 startPose() const;
  Eigen::Matrix3d startCovariance() const;

  template <class V>
  void visit(V& v) {
    v("association", association,
      "'known': observation ids name landmarks; 'nearest': nearest neighbour, Mahalanobis gates");
    v("range_std", range_std, "range 1-sigma [m] when an observation carries none");
    v("bearing_std", bearing_std, "bearing 1-sigma [rad] when an observation carries none");
    v("use_observation_std", use_observation_std, "use the stds observations carry when > 0");
    v("sigma_speed", sigma_speed, "control speed noise 1-sigma [m/s]");
    v("sigma_steer", sigma_steer, "car-like steering angle noise 1-sigma [rad]");
    v("sigma_turn_rate", sigma_turn_rate, "differential-drive turn-rate noise 1-sigma [rad/s]");
    v("outlier_gate", outlier_gate,
      "known ids: reject a sighting with squared Mahalanobis distance above this (0 = off)");
    v("association_gate", association_gate, "nearest: match below this squared distance");
    v("new_landmark_gate", new_landmark_gate, "nearest: new landmark above this squared distance");
    v("ambiguity_margin", ambiguity_margin,
      "nearest: drop a sighting when the second candidate is inside the gate and this close");
    v("initial_pose", initial_pose, "start pose in the map frame [x m, y m, theta rad]");
    v("initial_std", initial_std, "start pose 1-sigma [m, m, rad]");
    v("unscented", unscented, "unscented transform of the rbekf filter's pose");
  }
};

/// One range-bearing sighting (tessera::msg::LandmarkObservation without the runtime types).
struct Observation {
  int id = -1;             ///< landmark identity, -1 = unknown
  double range = 0;        ///< [m]
  double bearing = 0;      ///< [rad]
  double range_std = 0;    ///< [m] 0 = use the options'
  double bearing_std = 0;  ///< [rad] 0 = use the options'
};

struct RejectionCounts {
  std::uint64_t non_finite = 0, negative_range = 0, unknown_id = 0, gate = 0, ambiguous = 0,
                between_gates = 0, duplicate = 0, bad_control = 0;
  std::uint64_t total() const {
    return non_finite + negative_range + unknown_id + gate + ambiguous + between_gates + duplicate;
  }
};

struct LandmarkEstimate {
  int id = 0;
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();        ///< [m] map frame
  Eigen::Matrix2d covariance = Eigen::Matrix2d::Zero();  ///< [m²]
};

/// What one update() did.
struct UpdateResult {
  std::size_t corrected = 0, added = 0, rejected = 0;
};

class LandmarkFilter {
 public:
  virtual ~LandmarkFilter() = default;

  /// Moves the pose by one control (DriveInput::dt seconds). A non-finite control, dt < 0 or a
  /// car-like steering angle outside (-pi/2, pi/2) is counted (bad_control) and ignored.
  void predict(const tessera::landmark_slam::DriveInput& u);
  /// Observe, update, augment for one scan taken at the current pose.
  UpdateResult update(std::span<const Observation> observations, const tessera::Pose2& mount = {});

  virtual Eigen::Vector3d pose() const = 0;
  virtual Eigen::Matrix3d poseCovariance() const = 0;
  std::size_t landmarkCount() const { return ids_.size(); }
  /// Landmark `index` (0 <= index < landmarkCount(), in order of creation).
  LandmarkEstimate landmark(std::size_t index) const;
  std::vector<LandmarkEstimate> landmarks() const;

  const LandmarkSlamOptions& options() const { return options_; }
  const RejectionCounts& rejections() const { return rejections_; }
  /// Normalised innovation squared of every correction (2 dof: mean 2 when consistent).
  double nisSum() const { return nis_sum_; }
  std::uint64_t nisCount() const { return nis_count_; }

 protected:
  explicit LandmarkFilter(LandmarkSlamOptions options);

  struct Innovation {
    Eigen::Vector2d nu = Eigen::Vector2d::Zero();  ///< z - h (bearing wrapped)
    Eigen::Matrix2d S = Eigen::Matrix2d::Identity();
  };
  /// The linearised innovation of z against landmark `index` at the current state (gating).
  virtual LandmarkEstimate gaussian(std::size_t index) const = 0;  // id left 0
  virtual Innovation innovation(std::size_t index, const Eigen::Vector2d& z,
                                const Eigen::Matrix2d& R, const tessera::Pose2& mount) const = 0;
  virtual void doPredict(const tessera::landmark_slam::DriveInput& u,
                         const Eigen::Matrix2d& control_cov) = 0;
  /// Corrects with z of landmark `index`; returns the innovation it used.
  virtual Innovation correct(std::size_t index, const Eigen::Vector2d& z, const Eigen::Matrix2d& R,
                             const tessera::Pose2& mount) = 0;
  /// Appends a landmark initialised from z (index = landmarkCount() before the call).
  virtual void augment(const Eigen::Vector2d& z, const Eigen::Matrix2d& R,
                       const tessera::Pose2& mount) = 0;

  LandmarkSlamOptions options_;

 private:
  void addLandmark(int id, const Eigen::Vector2d& z, const Eigen::Matrix2d& R,
                   const tessera::Pose2& mount);

  std::vector<int> ids_;                        // by index
  std::unordered_map<int, std::size_t> index_;  // id -> index
  int next_id_ = 0;                             // nearest-neighbour mode
  RejectionCounts rejections_;
  double nis_sum_ = 0;
  std::uint64_t nis_count_ = 0;
};

/// EKF-SLAM baseline: one joint Gaussian over (pose, landmark 1, ..., landmark n); predict O(n),
/// each correction O(n²), augmentation O(n²) (the state is resized).
class EkfSlam final : public LandmarkFilter {
 public:
  /// Throws std::invalid_argument for invalid options.
  explicit EkfSlam(LandmarkSlamOptions options = {});
  Eigen::Vector3d pose() const override;
  Eigen::Matrix3d poseCovariance() const override;
  /// The joint state (x, y, theta, l1x, l1y, ...) and its covariance (copies).
  Eigen::VectorXd state() const;
  Eigen::MatrixXd covariance() const;
  /// Allocates room for `count` landmarks at once (the buffer otherwise grows by half).
  void reserveLandmarks(std::size_t count);

 private:
  LandmarkEstimate gaussian(std::size_t index) const override;
  Innovation innovation(std::size_t index, const Eigen::Vector2d& z, const Eigen::Matrix2d& R,
                        const tessera::Pose2& mount) const override;
  void doPredict(const tessera::landmark_slam::DriveInput& u,
                 const Eigen::Matrix2d& control_cov) override;
  Innovation correct(std::size_t index, const Eigen::Vector2d& z, const Eigen::Matrix2d& R,
                     const tessera::Pose2& mount) override;
  void augment(const Eigen::Vector2d& z, const Eigen::Matrix2d& R,
               const tessera::Pose2& mount) override;
  void grow(Eigen::Index capacity);

  Eigen::VectorXd x_;  // capacity >= n_
  Eigen::MatrixXd P_;  // capacity x capacity; the top-left n_ x n_ block is the covariance
  Eigen::Index n_ = 3;
};

/// The seed 004 filter: the pose by an unscented Kalman filter, each landmark by its own 2x2
/// Gaussian, pose-landmark and landmark-landmark correlations dropped (the Rao-Blackwellised
/// factorisation p(x | z, u) Π p(m_i | x, z) with one Gaussian for the path).
///  - predict: unscented transform over (pose, control noise), 5-D.
///  - correct (pose): one unscented transform over (pose, landmark i), 5-D, block-diagonal
///    prior, gives the predicted observation, S = P_zz + R and the pose-observation
///    cross-covariance; pose gain K_x = P_xz S⁻¹ (the UKF; landmark uncertainty acts as noise).
///  - correct (landmark i): its own 2x2 EKF (eqs. 13-14 of the paper), linearised at the prior
///    pose and landmark, with the pose uncertainty as extra noise:
///    S_m = H_m P_i H_mᵀ + H_x P_x H_xᵀ + R, K_m = P_i H_mᵀ S_m⁻¹.
///    Both halves use the same sighting, each treating the other's uncertainty as noise; no
///    pose-landmark cross-covariance is kept (the decomposition's approximation).
///  - augment: m = g(pose, z), P_m = G_x P_x G_xᵀ + G_z R G_zᵀ.
/// Each correction and augmentation is O(1) in the number of landmarks (nearest-neighbour
/// association still scans all landmarks).
class RbUkfSlam final : public LandmarkFilter {
 public:
  /// Throws std::invalid_argument for invalid options.
  explicit RbUkfSlam(LandmarkSlamOptions options = {});
  Eigen::Vector3d pose() const override { return pose_; }
  Eigen::Matrix3d poseCovariance() const override { return P_; }

 private:
  LandmarkEstimate gaussian(std::size_t index) const override;
  Innovation innovation(std::size_t index, const Eigen::Vector2d& z, const Eigen::Matrix2d& R,
                        const tessera::Pose2& mount) const override;
  void doPredict(const tessera::landmark_slam::DriveInput& u,
                 const Eigen::Matrix2d& control_cov) override;
  Innovation correct(std::size_t index, const Eigen::Vector2d& z, const Eigen::Matrix2d& R,
                     const tessera::Pose2& mount) override;
  void augment(const Eigen::Vector2d& z, const Eigen::Matrix2d& R,
               const tessera::Pose2& mount) override;

  Eigen::Vector3d pose_;
  Eigen::Matrix3d P_;
  struct Gaussian2 {
    Eigen::Vector2d mean;
    Eigen::Matrix2d cov;
  };
  std::vector<Gaussian2> landmarks_;
};

}  // namespace tessera::landmark_slam
