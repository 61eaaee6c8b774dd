#include <tessera/landmark_slam/landmark_filter.hpp>

#include <Eigen/LU>

#include <algorithm>

namespace tessera::landmark_slam {

// The covariance lives in the top-left n x n block of a buffer whose capacity grows by half,
// so augmenting does not copy the whole matrix every time (that would make building a map of n
// landmarks O(n³)).

EkfSlam::EkfSlam(LandmarkSlamOptions options) : LandmarkFilter(std::move(options)) {
  x_ = options_.startPose().vector();
  P_ = options_.startCovariance();
}

Eigen::Vector3d EkfSlam::pose() const {
  return x_.head<3>();
}

Eigen::Matrix3d EkfSlam::poseCovariance() const {
  return P_.topLeftCorner<3, 3>();
}

Eigen::MatrixXd EkfSlam::covariance() const {
  return P_.topLeftCorner(n_, n_);
}

Eigen::VectorXd EkfSlam::state() const {
  return x_.head(n_);
}

LandmarkEstimate EkfSlam::gaussian(std::size_t index) const {
  const Eigen::Index i0 = 3 + 2 * static_cast<Eigen::Index>(index);
  LandmarkEstimate e;
  e.mean = x_.segment<2>(i0);
  e.covariance = P_.block<2, 2>(i0, i0);
  return e;
}

void EkfSlam::doPredict(const tessera::landmark_slam::DriveInput& u,
                        const Eigen::Matrix2d& control_cov) {
  const tessera::landmark_slam::MotionStep step =
      tessera::landmark_slam::driveStep(x_.head<3>(), u);
  x_.head<3>() = step.pose;
  const Eigen::Index m = n_ - 3;
  const Eigen::Matrix3d Prr = P_.topLeftCorner<3, 3>();
  P_.topLeftCorner<3, 3>() = step.F_pose * Prr * step.F_pose.transpose() +
                             step.F_control * control_cov * step.F_control.transpose();
  if (m > 0) {
    const Eigen::MatrixXd Prl = step.F_pose * P_.block(0, 3, 3, m);
    P_.block(0, 3, 3, m) = Prl;
    P_.block(3, 0, m, 3) = Prl.transpose();
  }
}

LandmarkFilter::Innovation EkfSlam::innovation(std::size_t index, const Eigen::Vector2d& z,
                                               const Eigen::Matrix2d& R,
                                               const tessera::Pose2& mount) const {
  const Eigen::Index i0 = 3 + 2 * static_cast<Eigen::Index>(index);
  const auto pred =
      tessera::landmark_slam::predictRangeBearing(x_.head<3>(), x_.segment<2>(i0), mount);
  Eigen::Matrix<double, 2, 5> H;
  H << pred.H_pose, pred.H_landmark;
  Eigen::Matrix<double, 5, 5> C;
  C.topLeftCorner<3, 3>() = P_.topLeftCorner<3, 3>();
  C.topRightCorner<3, 2>() = P_.block<3, 2>(0, i0);
  C.bottomLeftCorner<2, 3>() = P_.block<2, 3>(i0, 0);
  C.bottomRightCorner<2, 2>() = P_.block<2, 2>(i0, i0);
  Innovation in;
  in.nu = {z[0] - pred.z[0], tessera::angleDiff(z[1], pred.z[1])};
  in.S = H * C * H.transpose() + R;
  return in;
}

LandmarkFilter::Innovation EkfSlam::correct(std::size_t index, const Eigen::Vector2d& z,
                                            const Eigen::Matrix2d& R, const tessera::Pose2& mount) {
  const Eigen::Index i0 = 3 + 2 * static_cast<Eigen::Index>(index);
  const auto pred =
      tessera::landmark_slam::predictRangeBearing(x_.head<3>(), x_.segment<2>(i0), mount);
  auto P = P_.topLeftCorner(n_, n_);
  // P Hᵀ touches only the pose and landmark columns: O(n); the covariance update is O(n²).
  const Eigen::MatrixXd PHt =
      P.leftCols<3>() * pred.H_pose.transpose() + P.middleCols<2>(i0) * pred.H_landmark.transpose();
  Innovation in;
  in.nu = {z[0] - pred.z[0], tessera::angleDiff(z[1], pred.z[1])};
  in.S = pred.H_pose * PHt.topRows<3>() + pred.H_landmark * PHt.middleRows<2>(i0) + R;
  in.S = 0.5 * (in.S + in.S.transpose()).eval();
  const Eigen::MatrixXd K = PHt * in.S.inverse();
  x_.head(n_) += K * in.nu;
  x_[2] = tessera::normalizeAngle(x_[2]);
  P.noalias() -= K * PHt.transpose();
  return in;
}

void EkfSlam::reserveLandmarks(std::size_t count) {
  const auto cap = 3 + 2 * static_cast<Eigen::Index>(count);
  if (cap > P_.rows()) grow(cap);
}

void EkfSlam::grow(Eigen::Index capacity) {
  Eigen::MatrixXd grown = Eigen::MatrixXd::Zero(capacity, capacity);
  grown.topLeftCorner(n_, n_) = P_.topLeftCorner(n_, n_);
  P_.swap(grown);
  x_.conservativeResize(capacity);
}

void EkfSlam::augment(const Eigen::Vector2d& z, const Eigen::Matrix2d& R,
                      const tessera::Pose2& mount) {
  const auto lf = tessera::landmark_slam::landmarkFromRangeBearing(x_.head<3>(), z, mount);
  const Eigen::Index n = n_;
  if (n + 2 > P_.rows()) grow(std::max<Eigen::Index>(P_.rows() + P_.rows() / 2, n + 2));
  x_.segment<2>(n) = lf.m;
  const Eigen::MatrixXd cross = lf.G_pose * P_.topLeftCorner(3, n);  // 2 x n
  P_.block(n, 0, 2, n) = cross;
  P_.block(0, n, n, 2) = cross.transpose();
  P_.block<2, 2>(n, n) = lf.G_pose * P_.topLeftCorner<3, 3>() * lf.G_pose.transpose() +
                         lf.G_z * R * lf.G_z.transpose();
  n_ = n + 2;
}

}  // namespace tessera::landmark_slam
