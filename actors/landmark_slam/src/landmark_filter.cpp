#include <tessera/landmark_slam/landmark_filter.hpp>

#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>

namespace tessera::landmark_slam {
namespace {

bool finite(const Observation& o) {
  return std::isfinite(o.range) && std::isfinite(o.bearing) && std::isfinite(o.range_std) &&
         std::isfinite(o.bearing_std);
}

}  // namespace

void LandmarkSlamOptions::validate() const {
  const auto fail = [](const std::string& what) { throw std::invalid_argument(what); };
  const auto positive = [&](double v, const char* name) {
    if (!(std::isfinite(v) && v > 0)) fail(std::string(name) + " must be > 0");
  };
  const auto non_negative = [&](double v, const char* name) {
    if (!(std::isfinite(v) && v >= 0)) fail(std::string(name) + " must be >= 0");
  };
  positive(range_std, "range_std");
  positive(bearing_std, "bearing_std");
  non_negative(sigma_speed, "sigma_speed");
  non_negative(sigma_steer, "sigma_steer");
  non_negative(sigma_turn_rate, "sigma_turn_rate");
  non_negative(outlier_gate, "outlier_gate");
  positive(association_gate, "association_gate");
  if (!(std::isfinite(new_landmark_gate) && new_landmark_gate >= association_gate))
    fail("new_landmark_gate must be >= association_gate");
  non_negative(ambiguity_margin, "ambiguity_margin");
  if (initial_pose.size() != 3) fail("initial_pose needs 3 values [x, y, theta]");
  for (const double x : initial_pose)
    if (!std::isfinite(x)) fail("initial_pose must be finite");
  if (initial_std.size() != 3) fail("initial_std needs 3 values");
  for (const double s : initial_std) non_negative(s, "initial_std");
  if (!(unscented.alpha > 0 && unscented.alpha <= 1)) fail("unscented.alpha must be in (0, 1]");
  if (!std::isfinite(unscented.beta)) fail("unscented.beta must be finite");
  if (!(3 + unscented.kappa > 0)) fail("unscented.kappa must be > -3");
}

tessera::Pose2 LandmarkSlamOptions::startPose() const {
  return {initial_pose.at(0), initial_pose.at(1), initial_pose.at(2)};
}

Eigen::Matrix3d LandmarkSlamOptions::startCovariance() const {
  const Eigen::Vector3d s(initial_std.at(0), initial_std.at(1), initial_std.at(2));
  return s.cwiseAbs2().asDiagonal();
}

LandmarkFilter::LandmarkFilter(LandmarkSlamOptions options) : options_(std::move(options)) {
  options_.validate();
}

LandmarkEstimate LandmarkFilter::landmark(std::size_t index) const {
  LandmarkEstimate e = gaussian(index);
  e.id = ids_.at(index);
  return e;
}

std::vector<LandmarkEstimate> LandmarkFilter::landmarks() const {
  std::vector<LandmarkEstimate> out;
  out.reserve(ids_.size());
  for (std::size_t i = 0; i < ids_.size(); ++i) out.push_back(landmark(i));
  return out;
}

void LandmarkFilter::predict(const tessera::landmark_slam::DriveInput& u) {
  const bool finite_u = std::isfinite(u.speed) && std::isfinite(u.steer) &&
                        std::isfinite(u.turn_rate) && std::isfinite(u.wheelbase) &&
                        std::isfinite(u.dt);
  if (!finite_u || u.dt < 0 || u.wheelbase < 0 ||
      (u.carLike() && std::abs(u.steer) >= 0.5 * std::numbers::pi)) {
    ++rejections_.bad_control;
    return;
  }
  if (u.dt == 0) return;
  const double turn = u.carLike() ? options_.sigma_steer : options_.sigma_turn_rate;
  const Eigen::Matrix2d M =
      Eigen::Vector2d(options_.sigma_speed * options_.sigma_speed, turn * turn).asDiagonal();
  doPredict(u, M);
}

UpdateResult LandmarkFilter::update(std::span<const Observation> observations,
                                    const tessera::Pose2& mount) {
  UpdateResult result;
  struct Match {
    std::size_t obs;
    std::size_t index;  // landmark; npos = new
    double d2;
  };
  constexpr std::size_t kNew = std::numeric_limits<std::size_t>::max();
  std::vector<Match> matches;
  std::vector<Eigen::Vector2d> zs(observations.size());
  std::vector<Eigen::Matrix2d> Rs(observations.size());
  std::unordered_map<int, std::size_t> new_in_scan;  // known ids first seen in this scan

  // Observe: validate and associate everything against the state before this scan.
  for (std::size_t k = 0; k < observations.size(); ++k) {
    const Observation& o = observations[k];
    if (!finite(o)) {
      ++rejections_.non_finite;
      continue;
    }
    if (!(o.range > 0)) {
      ++rejections_.negative_range;
      continue;
    }
    const bool own = options_.use_observation_std;
    const double rs = own && o.range_std > 0 ? o.range_std : options_.range_std;
    const double bs = own && o.bearing_std > 0 ? o.bearing_std : options_.bearing_std;
    zs[k] = {o.range, tessera::normalizeAngle(o.bearing)};
    Rs[k] = Eigen::Vector2d(rs * rs, bs * bs).asDiagonal();

    if (options_.association == Association::kKnownIds) {
      if (o.id < 0) {
        ++rejections_.unknown_id;
        continue;
      }
      const auto it = index_.find(o.id);
      if (it == index_.end()) {
        if (!new_in_scan.emplace(o.id, k).second) {
          ++rejections_.duplicate;
          continue;
        }
        matches.push_back({k, kNew, 0});
        continue;
      }
      const Innovation in = innovation(it->second, zs[k], Rs[k], mount);
      const double d2 = tessera::landmark_slam::mahalanobis2(in.nu, in.S);
      if (options_.outlier_gate > 0 && !(d2 <= options_.outlier_gate)) {
        ++rejections_.gate;
        continue;
      }
      matches.push_back({k, it->second, d2});
      continue;
    }

    double best = std::numeric_limits<double>::infinity(), second = best;
    std::size_t best_index = kNew;
    for (std::size_t i = 0; i < ids_.size(); ++i) {
      const Innovation in = innovation(i, zs[k], Rs[k], mount);
      const double d2 = tessera::landmark_slam::mahalanobis2(in.nu, in.S);
      if (d2 < best) {
        second = best;
        best = d2;
        best_index = i;
      } else if (d2 < second) {
        second = d2;
      }
    }
    if (best < options_.association_gate) {
      if (second < options_.association_gate && second - best < options_.ambiguity_margin) {
        ++rejections_.ambiguous;
        continue;
      }
      matches.push_back({k, best_index, best});
    } else if (best > options_.new_landmark_gate) {
      matches.push_back({k, kNew, best});
    } else {
      ++rejections_.between_gates;
    }
  }

  // One observation per landmark and scan: the closest keeps it (known ids: the first).
  if (options_.association == Association::kKnownIds) {
    std::unordered_map<std::size_t, std::size_t> first;
    std::vector<Match> kept;
    for (const Match& m : matches) {
      if (m.index != kNew && !first.emplace(m.index, m.obs).second) {
        ++rejections_.duplicate;
        continue;
      }
      kept.push_back(m);
    }
    matches.swap(kept);
  } else {
    std::unordered_map<std::size_t, std::size_t> owner;  // landmark -> position in matches
    std::vector<bool> dropped(matches.size(), false);
    for (std::size_t j = 0; j < matches.size(); ++j) {
      if (matches[j].index == kNew) continue;
      const auto [it, inserted] = owner.emplace(matches[j].index, j);
      if (inserted) continue;
      const std::size_t loser = matches[it->second].d2 <= matches[j].d2 ? j : it->second;
      if (loser == it->second) it->second = j;
      dropped[loser] = true;
      ++rejections_.duplicate;
    }
    std::vector<Match> kept;
    for (std::size_t j = 0; j < matches.size(); ++j)
      if (!dropped[j]) kept.push_back(matches[j]);
    matches.swap(kept);
  }

  // Update, then augment.
  for (const Match& m : matches) {
    if (m.index == kNew) continue;
    const Innovation in = correct(m.index, zs[m.obs], Rs[m.obs], mount);
    const double nis = tessera::landmark_slam::mahalanobis2(in.nu, in.S);
    if (std::isfinite(nis)) {
      nis_sum_ += nis;
      ++nis_count_;
    }
    ++result.corrected;
  }
  for (const Match& m : matches) {
    if (m.index != kNew) continue;
    const int id =
        options_.association == Association::kKnownIds ? observations[m.obs].id : next_id_++;
    addLandmark(id, zs[m.obs], Rs[m.obs], mount);
    ++result.added;
  }
  result.rejected = observations.size() - result.corrected - result.added;
  return result;
}

void LandmarkFilter::addLandmark(int id, const Eigen::Vector2d& z, const Eigen::Matrix2d& R,
                                 const tessera::Pose2& mount) {
  augment(z, R, mount);
  index_.emplace(id, ids_.size());
  ids_.push_back(id);
}

}  // namespace tessera::landmark_slam
