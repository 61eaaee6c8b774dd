// LoopVerifier: direct-index matching, RANSAC PnP, the 3D check and the covariance of the loop's
// relative pose (see the header).
#include <tessera/visual_slam/loop_verifier.hpp>

#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace tessera::visual_slam {
namespace {

using Matrix6d = Eigen::Matrix<double, 6, 6>;

Eigen::Isometry3d fromParameters(const Eigen::Matrix<double, 6, 1>& p) {
  // PoseEstimator's parameters: (rotation vector, translation) of camera_from_world.
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  const double angle = p.head<3>().norm();
  if (angle > 0) T.linear() = Eigen::AngleAxisd(angle, p.head<3>() / angle).toRotationMatrix();
  T.translation() = p.tail<3>();
  return T;
}

Eigen::Matrix<double, 6, 1> toParameters(const Eigen::Isometry3d& T) {
  const Eigen::AngleAxisd aa(T.rotation());
  Eigen::Matrix<double, 6, 1> p;
  p << aa.axis() * aa.angle(), T.translation();
  return p;
}

/// Covariance of candidate_from_query (right perturbation, (x y z rx ry rz)) from that of the
/// PnP parameters of query_from_candidate, by central differences of the map between them.
Matrix6d relativeCovariance(const Eigen::Isometry3d& query_from_candidate,
                            const Matrix6d& pnp_covariance) {
  const Eigen::Matrix<double, 6, 1> p0 = toParameters(query_from_candidate);
  const Eigen::Isometry3d rel0_inv = query_from_candidate;  // (candidate_from_query)^-1
  Matrix6d J;
  constexpr double h = 1e-6;
  for (int k = 0; k < 6; ++k) {
    Eigen::Matrix<double, 6, 1> cols[2];
    for (int s = 0; s < 2; ++s) {
      Eigen::Matrix<double, 6, 1> p = p0;
      p[k] += s == 0 ? h : -h;
      // E = rel0^-1 rel(p) with rel(p) = T(p)^-1: the right-perturbation error.
      const Eigen::Isometry3d E = rel0_inv * fromParameters(p).inverse();
      const Eigen::AngleAxisd aa(E.rotation());
      cols[s] << E.translation(), aa.axis() * aa.angle();
    }
    J.col(k) = (cols[0] - cols[1]) / (2 * h);
  }
  return J * pnp_covariance * J.transpose();
}

}  // namespace

void LoopVerifierOptions::validate() const {
  auto need = [](bool ok, const char* what) {
    if (!ok) throw std::invalid_argument(std::string("loop verifier: ") + what);
  };
  need(direct_depth >= 0, "direct_depth must be >= 0");
  need(std::isfinite(ratio) && ratio > 0 && ratio <= 1, "ratio must be in (0, 1]");
  need(max_distance >= 0 && max_distance <= 256, "max_distance must be in [0, 256]");
  need(min_matches >= 4, "min_matches must be >= 4");
  need(min_inliers >= 4, "min_inliers must be >= 4");
  need(std::isfinite(min_inlier_ratio) && min_inlier_ratio >= 0 && min_inlier_ratio <= 1,
       "min_inlier_ratio must be in [0, 1]");
  need(std::isfinite(max_rms_px) && max_rms_px > 0, "max_rms_px must be > 0");
  need(std::isfinite(max_point_distance) && max_point_distance >= 0,
       "max_point_distance must be >= 0");
  need(std::isfinite(max_point_distance_rel) && max_point_distance_rel >= 0,
       "max_point_distance_rel must be >= 0");
  need(std::isfinite(min_depth_agreement) && min_depth_agreement >= 0 && min_depth_agreement <= 1,
       "min_depth_agreement must be in [0, 1]");
  need(std::isfinite(min_coverage) && min_coverage >= 0 && min_coverage <= 1,
       "min_coverage must be in [0, 1]");
  need(std::isfinite(max_pose_disagreement_m) && max_pose_disagreement_m >= 0,
       "max_pose_disagreement_m must be >= 0");
  need(std::isfinite(max_pose_disagreement_rad) && max_pose_disagreement_rad >= 0,
       "max_pose_disagreement_rad must be >= 0");
  need(std::isfinite(min_sigma_translation) && min_sigma_translation > 0,
       "min_sigma_translation must be > 0");
  need(std::isfinite(min_sigma_rotation) && min_sigma_rotation > 0,
       "min_sigma_rotation must be > 0");
  try {
    pnp.validate();
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string("loop verifier: pnp: ") + e.what());
  }
}

std::string_view rejectionName(LoopRejection r) {
  switch (r) {
    case LoopRejection::kNone:
      return "none";
    case LoopRejection::kTooFewMatches:
      return "too_few_matches";
    case LoopRejection::kPnpFailed:
      return "pnp_failed";
    case LoopRejection::kTooFewInliers:
      return "too_few_inliers";
    case LoopRejection::kLowInlierRatio:
      return "low_inlier_ratio";
    case LoopRejection::kHighError:
      return "high_error";
    case LoopRejection::kDepthDisagrees:
      return "depth_disagrees";
    case LoopRejection::kLowCoverage:
      return "low_coverage";
    case LoopRejection::kPoseDisagrees:
      return "pose_disagrees";
  }
  return "?";
}

std::string LoopView::check() const {
  const std::size_t n = pixels.size();
  if (points.size() != n) return "points and pixels differ in number";
  if (n > 0 && (descriptors.type() != CV_8UC1 || descriptors.cols != kDescriptorBytes ||
                static_cast<std::size_t>(descriptors.rows) != n))
    return "descriptors are not one 32-byte CV_8UC1 row per feature";
  for (const auto& px : pixels)
    if (!px.allFinite()) return "non-finite pixel";
  for (const auto& [node, idx] : features)
    for (int i : idx)
      if (i < 0 || static_cast<std::size_t>(i) >= n) return "feature index out of range";
  return "";
}

std::vector<std::pair<int, int>> matchByDirectIndex(const LoopView& query,
                                                    const LoopView& candidate, double ratio,
                                                    int max_distance) {
  // best[j]: (distance, query index) of the closest query feature claiming candidate feature j.
  std::vector<std::pair<int, int>> best(candidate.size(), {std::numeric_limits<int>::max(), -1});
  auto q_it = query.features.begin();
  auto c_it = candidate.features.begin();
  while (q_it != query.features.end() && c_it != candidate.features.end()) {
    if (q_it->first < c_it->first) {
      ++q_it;
    } else if (c_it->first < q_it->first) {
      ++c_it;
    } else {
      for (int qi : q_it->second) {
        const BinaryDescriptor dq = toBinaryDescriptor(query.descriptors.ptr<std::uint8_t>(qi));
        int d1 = std::numeric_limits<int>::max(), d2 = d1, j1 = -1;
        for (int cj : c_it->second) {
          if (!candidate.points[cj].allFinite()) continue;
          const int d =
              hammingDistance(dq, toBinaryDescriptor(candidate.descriptors.ptr<std::uint8_t>(cj)));
          if (d < d1) {
            d2 = d1;
            d1 = d;
            j1 = cj;
          } else if (d < d2) {
            d2 = d;
          }
        }
        if (j1 < 0 || d1 > max_distance) continue;
        if (d2 != std::numeric_limits<int>::max() && !(d1 < ratio * d2)) continue;
        if (d1 < best[j1].first) best[j1] = {d1, qi};
      }
      ++q_it;
      ++c_it;
    }
  }
  std::vector<std::pair<int, int>> out;
  for (std::size_t j = 0; j < best.size(); ++j)
    if (best[j].second >= 0) out.emplace_back(best[j].second, static_cast<int>(j));
  std::sort(out.begin(), out.end());
  return out;
}

LoopVerifier::LoopVerifier(const LoopVerifierOptions& options, const PinholeCamera& camera)
    : options_((options.validate(), options)), camera_(camera), estimator_(options.pnp, camera) {}

LoopVerification LoopVerifier::verify(const LoopView& query, const LoopView& candidate) const {
  LoopVerification r;
  if (!query.check().empty() || !candidate.check().empty()) return r;
  const auto pairs = matchByDirectIndex(query, candidate, options_.ratio, options_.max_distance);
  r.matches = static_cast<int>(pairs.size());
  if (r.matches < options_.min_matches) return r;

  std::vector<Eigen::Vector3d> points;
  std::vector<Eigen::Vector2d> pixels;
  std::vector<double> depths;
  for (const auto& [qi, cj] : pairs) {
    points.push_back(candidate.points[cj]);
    pixels.push_back(query.pixels[qi]);
    const Eigen::Vector3d& qp = query.points[qi];
    depths.push_back(qp.allFinite() ? qp.z() : std::numeric_limits<double>::quiet_NaN());
  }
  const PoseEstimate est = estimator_.estimate(points, pixels, std::nullopt, &depths);
  if (!est.ok) {
    r.rejection = LoopRejection::kPnpFailed;
    return r;
  }
  r.inliers = static_cast<int>(est.inliers.size());
  r.inlier_ratio = static_cast<double>(r.inliers) / r.matches;
  r.rms_px = est.rms_px;
  const Eigen::Isometry3d& query_from_candidate = est.camera_from_world;
  int with_depth = 0;
  std::vector<std::pair<int, int>> agreeing;  // inliers whose depths pass the 3D check
  constexpr int kCells = 4;
  std::array<bool, kCells * kCells> covered{};
  for (int i : est.inliers) {
    const auto [qi, cj] = pairs[static_cast<std::size_t>(i)];
    r.inlier_pairs.emplace_back(qi, cj);
    const Eigen::Vector2d& px = query.pixels[qi];
    const int cx = std::clamp(static_cast<int>(px.x() * kCells / camera_.width), 0, kCells - 1);
    const int cy = std::clamp(static_cast<int>(px.y() * kCells / camera_.height), 0, kCells - 1);
    covered[static_cast<std::size_t>(cy * kCells + cx)] = true;
    const Eigen::Vector3d& qp = query.points[qi];
    if (!qp.allFinite()) continue;
    ++with_depth;
    const double err = (query_from_candidate * candidate.points[cj] - qp).norm();
    if (err <= options_.max_point_distance + options_.max_point_distance_rel * qp.z())
      agreeing.emplace_back(qi, cj);
  }
  const auto agree = static_cast<int>(agreeing.size());
  r.depth_agreement = with_depth > 0 ? static_cast<double>(agree) / with_depth : 0.0;
  r.coverage =
      static_cast<double>(std::count(covered.begin(), covered.end(), true)) / (kCells * kCells);
  r.candidate_from_query = query_from_candidate.inverse();
  bool fitted = false;
  if (options_.align_3d && agree >= 3) {
    // Rigid 3D-3D fit (least squares, Eigen's Umeyama) of the inliers that passed the 3D check:
    // at Kinect range the measured depths fix the pose better than reprojections of a few dozen
    // points; the check keeps a wrong depth from dragging the fit.
    Eigen::Matrix3Xd src(3, agree), dst(3, agree);
    for (int c = 0; c < agree; ++c) {
      src.col(c) = candidate.points[agreeing[static_cast<std::size_t>(c)].second];
      dst.col(c) = query.points[agreeing[static_cast<std::size_t>(c)].first];
    }
    const Eigen::Matrix4d m = Eigen::umeyama(src, dst, false);
    const Eigen::Isometry3d fit(m);
    if (fit.matrix().allFinite()) {
      fitted = true;
      r.candidate_from_query = fit.inverse();
      r.fit_rms_m = std::sqrt((fit * src - dst).colwise().squaredNorm().mean());
      const Eigen::Isometry3d diff = query_from_candidate.inverse() * fit;
      r.pose_disagreement_m = diff.translation().norm();
      r.pose_disagreement_rad = Eigen::AngleAxisd(diff.rotation()).angle();
    }
  }

  if (r.inliers < options_.min_inliers)
    r.rejection = LoopRejection::kTooFewInliers;
  else if (r.inlier_ratio < options_.min_inlier_ratio)
    r.rejection = LoopRejection::kLowInlierRatio;
  else if (r.rms_px > options_.max_rms_px)
    r.rejection = LoopRejection::kHighError;
  else if (r.depth_agreement < options_.min_depth_agreement)
    r.rejection = LoopRejection::kDepthDisagrees;
  else if (r.coverage < options_.min_coverage)
    r.rejection = LoopRejection::kLowCoverage;
  else if (fitted && (r.pose_disagreement_m > options_.max_pose_disagreement_m ||
                      r.pose_disagreement_rad > options_.max_pose_disagreement_rad))
    r.rejection = LoopRejection::kPoseDisagrees;
  else
    r.rejection = LoopRejection::kNone;
  r.accepted = r.rejection == LoopRejection::kNone;

  Matrix6d cov = relativeCovariance(query_from_candidate, est.covariance);
  if (!cov.allFinite()) cov.setZero();
  cov = 0.5 * (cov + cov.transpose());
  const double st2 = options_.min_sigma_translation * options_.min_sigma_translation;
  const double sr2 = options_.min_sigma_rotation * options_.min_sigma_rotation;
  for (int k = 0; k < 6; ++k) cov(k, k) += k < 3 ? st2 : sr2;  // floor: adds, keeps it SPD
  r.covariance = cov;
  return r;
}

}  // namespace tessera::visual_slam
