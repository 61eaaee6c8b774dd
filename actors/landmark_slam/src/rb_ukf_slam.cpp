#include <tessera/landmark_slam/landmark_filter.hpp>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>

namespace tessera::landmark_slam {
namespace {

// Symmetric part with negative eigenvalues (rounding) clamped to zero, so the next unscented
// transform always gets a valid covariance.
template <int N>
Eigen::Matrix<double, N, N> nearestPsd(const Eigen::Matrix<double, N, N>& m) {
  const Eigen::Matrix<double, N, N> s = 0.5 * (m + m.transpose());
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, N, N>> eig(s);
  if (eig.eigenvalues().minCoeff() >= 0) return s;
  return eig.eigenvectors() * eig.eigenvalues().cwiseMax(0.0).asDiagonal() *
         eig.eigenvectors().transpose();
}

}  // namespace

RbUkfSlam::RbUkfSlam(LandmarkSlamOptions options) : LandmarkFilter(std::move(options)) {
  pose_ = options_.startPose().vector();
  P_ = options_.startCovariance();
}

LandmarkEstimate RbUkfSlam::gaussian(std::size_t index) const {
  LandmarkEstimate e;
  e.mean = landmarks_.at(index).mean;
  e.covariance = landmarks_.at(index).cov;
  return e;
}

void RbUkfSlam::doPredict(const tessera::landmark_slam::DriveInput& u,
                          const Eigen::Matrix2d& control_cov) {
  // Sigma points over (pose, speed noise, steering / turn-rate noise).
  Eigen::VectorXd mean = Eigen::VectorXd::Zero(5);
  mean.head<3>() = pose_;
  Eigen::MatrixXd C = Eigen::MatrixXd::Zero(5, 5);
  C.topLeftCorner<3, 3>() = P_;
  C.bottomRightCorner<2, 2>() = control_cov;
  const auto r = tessera::landmark_slam::unscentedTransform(
      mean, C,
      [&u](const Eigen::VectorXd& a) -> Eigen::VectorXd {
        tessera::landmark_slam::DriveInput v = u;
        v.speed += a[3];
        (v.carLike() ? v.steer : v.turn_rate) += a[4];
        return tessera::landmark_slam::driveStep(a.head<3>(), v).pose;
      },
      {2}, options_.unscented);
  pose_ = r.mean;
  P_ = nearestPsd<3>(r.covariance);
}

LandmarkFilter::Innovation RbUkfSlam::innovation(std::size_t index, const Eigen::Vector2d& z,
                                                 const Eigen::Matrix2d& R,
                                                 const tessera::Pose2& mount) const {
  // Gating only: linearised, so that scanning every landmark stays cheap.
  const Gaussian2& l = landmarks_[index];
  const auto pred = tessera::landmark_slam::predictRangeBearing(pose_, l.mean, mount);
  Innovation in;
  in.nu = {z[0] - pred.z[0], tessera::angleDiff(z[1], pred.z[1])};
  in.S = pred.H_pose * P_ * pred.H_pose.transpose() +
         pred.H_landmark * l.cov * pred.H_landmark.transpose() + R;
  return in;
}

LandmarkFilter::Innovation RbUkfSlam::correct(std::size_t index, const Eigen::Vector2d& z,
                                              const Eigen::Matrix2d& R,
                                              const tessera::Pose2& mount) {
  Gaussian2& l = landmarks_[index];
  Eigen::VectorXd mean(5);
  mean << pose_, l.mean;
  Eigen::MatrixXd C = Eigen::MatrixXd::Zero(5, 5);
  C.topLeftCorner<3, 3>() = P_;
  C.bottomRightCorner<2, 2>() = l.cov;
  const auto r = tessera::landmark_slam::unscentedTransform(
      mean, C,
      [&mount](const Eigen::VectorXd& a) -> Eigen::VectorXd {
        return tessera::landmark_slam::predictRangeBearing(a.head<3>(), a.tail<2>(), mount).z;
      },
      {1}, options_.unscented);
  Innovation in;
  in.nu = {z[0] - r.mean[0], tessera::angleDiff(z[1], r.mean[1])};
  in.S = r.covariance + R;
  in.S = 0.5 * (in.S + in.S.transpose()).eval();
  const Eigen::Matrix2d S_inv = in.S.inverse();

  // Pose: the UKF gain from the unscented cross-covariance.
  const Eigen::Matrix<double, 3, 2> Kx = r.cross.topRows<3>() * S_inv;
  // Landmark: its own 2x2 EKF, linearised at the prior pose and landmark, with the pose
  // uncertainty as extra observation noise. Its innovation covariance bounds H_m P_m H_mᵀ + R
  // from above, so the landmark covariance stays positive definite (the unscented S need not,
  // mixed with a Jacobian, at short range).
  const auto pred = tessera::landmark_slam::predictRangeBearing(pose_, l.mean, mount);
  const Eigen::Vector2d nu_m(z[0] - pred.z[0], tessera::angleDiff(z[1], pred.z[1]));
  Eigen::Matrix2d S_m = pred.H_landmark * l.cov * pred.H_landmark.transpose() +
                        pred.H_pose * P_ * pred.H_pose.transpose() + R;
  S_m = 0.5 * (S_m + S_m.transpose()).eval();
  const Eigen::Matrix2d Km = l.cov * pred.H_landmark.transpose() * S_m.inverse();

  pose_ += Kx * in.nu;
  pose_[2] = tessera::normalizeAngle(pose_[2]);
  P_ = nearestPsd<3>(P_ - Kx * in.S * Kx.transpose());
  l.mean += Km * nu_m;
  l.cov = nearestPsd<2>(l.cov - Km * S_m * Km.transpose());
  return in;
}

void RbUkfSlam::augment(const Eigen::Vector2d& z, const Eigen::Matrix2d& R,
                        const tessera::Pose2& mount) {
  const auto lf = tessera::landmark_slam::landmarkFromRangeBearing(pose_, z, mount);
  landmarks_.push_back(
      {lf.m, lf.G_pose * P_ * lf.G_pose.transpose() + lf.G_z * R * lf.G_z.transpose()});
}

}  // namespace tessera::landmark_slam
