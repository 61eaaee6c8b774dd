// Tracker: constant-velocity prediction, local-map tracking, previous-frame fallback,
// relocalisation and keyframe insertion (see the header).
#include <tessera/visual_slam/tracker.hpp>

#include <opencv2/imgproc.hpp>

#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <utility>

namespace tessera::visual_slam {

namespace {

using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

// The depth the frame measured at each of `keypoints` [m], NaN where it has none.
std::vector<double> measuredDepths(const Features& f, const std::vector<int>& keypoints) {
  std::vector<double> z;
  z.reserve(keypoints.size());
  for (int k : keypoints) {
    const auto i = static_cast<std::size_t>(k);
    z.push_back(f.has_depth[i] ? f.points[i].z() : std::nan(""));
  }
  return z;
}

std::string sizeText(int w, int h) {
  return std::to_string(w) + "x" + std::to_string(h);
}

}  // namespace

struct Tracker::Attempt {
  PoseEstimate estimate;
  std::size_t matches = 0;
  // The correspondences given to PnP: current keypoint and the map's world point.
  std::vector<int> keypoints;
  std::vector<Eigen::Vector3d> points;
  std::vector<std::int64_t> point_ids;  // the map points' ids (-1: none)
  bool ok(int min_inliers) const {
    return estimate.ok && static_cast<int>(estimate.inliers.size()) >= min_inliers;
  }
};

void TrackerOptions::validate() const {
  extractor.validate();
  matcher.validate();
  pnp.validate();
  keyframes.validate();
  local_ba.validate();
  const auto bad = [](const std::string& what) { throw std::invalid_argument("tracker: " + what); };
  if (local_map_keyframes < 1) bad("local_map_keyframes must be >= 1");
  if (local_map_nearby < 0) bad("local_map_nearby must be >= 0");
  if (!(local_map_nearby_motion >= 0) || !std::isfinite(local_map_nearby_motion))
    bad("local_map_nearby_motion must be >= 0");
  if (!(search_radius > 0) || !std::isfinite(search_radius)) bad("search_radius must be > 0");
  if (!(local_map_max_distance >= 0) || !std::isfinite(local_map_max_distance))
    bad("local_map_max_distance must be >= 0");
  if (!(local_map_ratio > 0 && local_map_ratio <= 1)) bad("local_map_ratio must be in (0, 1]");
  if (min_tracking_inliers < pnp.min_inliers)
    bad("min_tracking_inliers must be >= pnp_min_inliers");
  if (min_init_features < 4) bad("min_init_features must be >= 4");
  if (relocalisation_min_inliers < pnp.min_inliers)
    bad("relocalisation_min_inliers must be >= pnp_min_inliers");
  if (relocalisation_candidates < 1) bad("relocalisation_candidates must be >= 1");
  if (insert_after_large_drops < 0) bad("insert_after_large_drops must be >= 0");
}

std::string_view stateName(TrackingState s) {
  switch (s) {
    case TrackingState::kSkipped:
      return "skipped";
    case TrackingState::kInitialised:
      return "initialised";
    case TrackingState::kTracking:
      return "tracking";
    case TrackingState::kTrackingPrevious:
      return "tracking_previous";
    case TrackingState::kRelocalised:
      return "relocalised";
    case TrackingState::kLost:
      return "lost";
  }
  return "?";
}

Tracker::Tracker(const TrackerOptions& options, const PinholeCamera& camera)
    : options_(options),
      camera_(camera),
      extractor_(options.extractor, camera),
      matcher_(options.matcher),
      estimator_(options.pnp, camera),
      selector_(options.keyframes) {
  options_.validate();
}

std::string Tracker::checkFrame(const RgbdFrame& frame) const {
  const cv::Mat& im = frame.image;
  if (im.empty()) return "empty image";
  if (im.type() != CV_8UC1 && im.type() != CV_8UC3) return "image is not 8-bit grey or RGB";
  if (im.cols != camera_.width || im.rows != camera_.height)
    return "image is " + sizeText(im.cols, im.rows) + ", the camera " +
           sizeText(camera_.width, camera_.height);
  if (!frame.depth.empty()) {
    if (frame.depth.type() != CV_16UC1) return "depth is not 16-bit single-channel";
    if (frame.depth.size() != im.size())
      return "depth is " + sizeText(frame.depth.cols, frame.depth.rows) + ", the image " +
             sizeText(im.cols, im.rows);
    if (!(frame.depth_scale > 0) || !std::isfinite(frame.depth_scale))
      return "depth_scale is not a positive number";
  }
  return {};
}

Keyframe Tracker::makeKeyframe(const Features& f, const Eigen::Isometry3d& camera_to_world,
                               std::size_t frame, double timestamp, const Attempt* tracked) const {
  // A feature that was a PnP inlier keeps the map point it matched, where its own depth agrees
  // with it: the map then stays anchored where the point was first seen instead of being
  // re-measured (and re-drifted) by every keyframe.
  std::vector<const Eigen::Vector3d*> reuse(f.size(), nullptr);
  std::vector<std::int64_t> reuse_id(f.size(), -1);
  if (tracked != nullptr && tracked->estimate.ok)
    for (int c : tracked->estimate.inliers) {
      const auto ci = static_cast<std::size_t>(c);
      const auto kp = static_cast<std::size_t>(tracked->keypoints[ci]);
      reuse[kp] = &tracked->points[ci];
      reuse_id[kp] = tracked->point_ids[ci];
    }
  const auto& eo = options_.extractor;
  Keyframe k;
  k.frame = frame;
  k.timestamp = timestamp;
  k.camera_to_world = camera_to_world;
  std::vector<int> rows;
  rows.reserve(f.with_depth);
  for (std::size_t i = 0; i < f.size(); ++i)
    if (f.has_depth[i]) rows.push_back(static_cast<int>(i));
  k.keypoints.reserve(rows.size());
  k.points_camera.reserve(rows.size());
  k.points_world.reserve(rows.size());
  k.point_ids.reserve(rows.size());
  k.descriptors.create(static_cast<int>(rows.size()), f.descriptors.cols, f.descriptors.type());
  for (std::size_t r = 0; r < rows.size(); ++r) {
    const auto i = static_cast<std::size_t>(rows[r]);
    Eigen::Vector3d world = camera_to_world * f.points[i];
    std::int64_t id = -1;
    if (reuse[i] != nullptr && options_.reuse_map_points) {
      const double tolerance = eo.depth_edge_abs + eo.depth_edge_rel * f.points[i].z();
      if ((*reuse[i] - world).norm() < tolerance) {
        world = *reuse[i];
        id = reuse_id[i];
      }
    }
    k.point_ids.push_back(id);
    k.keypoints.push_back(f.keypoints[i]);
    k.points_camera.push_back(f.points[i]);
    k.points_world.push_back(world);
    f.descriptors.row(rows[r]).copyTo(k.descriptors.row(static_cast<int>(r)));
  }
  return k;
}

Tracker::Attempt Tracker::trackLocalMap(const Features& f, const Eigen::Isometry3d& predicted,
                                        FrameTiming& timing) const {
  const auto t0 = Clock::now();
  Attempt a;
  // The local map: every point of the last local_map_keyframes keyframes and of the older
  // keyframes nearest the prediction.
  struct MapRef {
    const Keyframe* kf;
    int index;
  };
  const std::size_t recent = static_cast<std::size_t>(options_.local_map_keyframes);
  const std::size_t first = keyframes_.size() > recent ? keyframes_.size() - recent : 0;
  std::vector<std::size_t> chosen;
  for (std::size_t k = first; k < keyframes_.size(); ++k) chosen.push_back(k);
  std::vector<std::pair<double, std::size_t>> nearby;
  for (std::size_t k = 0; k < first; ++k) {
    if (keyframes_[k].points_world.empty()) continue;  // forgotten (lifelong mode)
    const double e = motionSize(keyframes_[k].camera_to_world.inverse() * predicted);
    if (e < options_.local_map_nearby_motion) nearby.emplace_back(e, k);
  }
  const std::size_t extra =
      std::min(nearby.size(), static_cast<std::size_t>(options_.local_map_nearby));
  std::partial_sort(nearby.begin(), nearby.begin() + static_cast<std::ptrdiff_t>(extra),
                    nearby.end());
  for (std::size_t i = 0; i < extra; ++i) chosen.push_back(nearby[i].second);
  std::vector<MapRef> map;
  for (std::size_t k : chosen)
    for (std::size_t j = 0; j < keyframes_[k].points_world.size(); ++j)
      map.push_back({&keyframes_[k], static_cast<int>(j)});
  if (map.empty() || f.size() == 0) {
    timing.local_map_ms += msSince(t0);
    return a;
  }

  // Current keypoints binned in a grid of search_radius cells.
  const double radius = options_.search_radius;
  const int gw = static_cast<int>(std::ceil(camera_.width / radius));
  const int gh = static_cast<int>(std::ceil(camera_.height / radius));
  std::vector<std::vector<int>> grid(static_cast<std::size_t>(gw * gh));
  for (std::size_t i = 0; i < f.size(); ++i) {
    const auto& pt = f.keypoints[i].pt;
    const int gx = std::clamp(static_cast<int>(pt.x / radius), 0, gw - 1);
    const int gy = std::clamp(static_cast<int>(pt.y / radius), 0, gh - 1);
    grid[static_cast<std::size_t>(gy * gw + gx)].push_back(static_cast<int>(i));
  }
  const double max_distance = options_.local_map_max_distance > 0
                                  ? options_.local_map_max_distance
                                  : (options_.extractor.type == FeatureType::kSift ? 250.0 : 64.0);
  const Eigen::Isometry3d camera_from_world = predicted.inverse();

  // Per map point: its best keypoint (or -1) and the distance.
  std::vector<int> best_kp(map.size(), -1);
  std::vector<double> best_d(map.size(), 0);
  tbb::parallel_for(std::size_t{0}, map.size(), [&](std::size_t m) {
    const Keyframe& kf = *map[m].kf;
    const int j = map[m].index;
    const Eigen::Vector3d c = camera_from_world * kf.points_world[static_cast<std::size_t>(j)];
    if (c.z() < options_.extractor.min_depth) return;
    const Eigen::Vector2d uv = camera_.project(c);
    if (!camera_.inside(uv)) return;
    const int cx = static_cast<int>(uv.x() / radius), cy = static_cast<int>(uv.y() / radius);
    double d1 = std::numeric_limits<double>::infinity(), d2 = d1;
    int k1 = -1;
    for (int y = std::max(0, cy - 1); y <= std::min(gh - 1, cy + 1); ++y) {
      for (int x = std::max(0, cx - 1); x <= std::min(gw - 1, cx + 1); ++x) {
        for (int i : grid[static_cast<std::size_t>(y * gw + x)]) {
          const auto& pt = f.keypoints[static_cast<std::size_t>(i)].pt;
          const double du = pt.x - uv.x(), dv = pt.y - uv.y();
          if (du * du + dv * dv > radius * radius) continue;
          const double d = descriptorDistance(kf.descriptors, j, f.descriptors, i);
          if (d < d1) {
            d2 = d1;
            d1 = d;
            k1 = i;
          } else if (d < d2) {
            d2 = d;
          }
        }
      }
    }
    if (k1 < 0 || d1 > max_distance || !(d1 < options_.local_map_ratio * d2)) return;
    best_kp[m] = k1;
    best_d[m] = d1;
  });
  // One map point per keypoint: the closest in descriptor space.
  std::vector<int> owner(f.size(), -1);
  for (std::size_t m = 0; m < map.size(); ++m) {
    const int k = best_kp[m];
    if (k < 0) continue;
    int& o = owner[static_cast<std::size_t>(k)];
    if (o < 0 || best_d[m] < best_d[static_cast<std::size_t>(o)]) o = static_cast<int>(m);
  }
  std::vector<Eigen::Vector3d> points;
  std::vector<Eigen::Vector2d> pixels;
  for (std::size_t k = 0; k < f.size(); ++k) {
    const int m = owner[k];
    if (m < 0) continue;
    const auto& ref = map[static_cast<std::size_t>(m)];
    points.push_back(ref.kf->points_world[static_cast<std::size_t>(ref.index)]);
    pixels.emplace_back(f.keypoints[k].pt.x, f.keypoints[k].pt.y);
    a.keypoints.push_back(static_cast<int>(k));
    a.point_ids.push_back(ref.kf->point_ids[static_cast<std::size_t>(ref.index)]);
  }
  timing.local_map_ms += msSince(t0);
  a.matches = points.size();
  if (static_cast<int>(points.size()) < options_.min_tracking_inliers) return a;
  const auto t1 = Clock::now();
  const std::vector<double> depths = measuredDepths(f, a.keypoints);
  a.estimate = estimator_.estimate(points, pixels, camera_from_world, &depths);
  timing.pnp_ms += msSince(t1);
  a.points = std::move(points);
  return a;
}

Tracker::Attempt Tracker::trackFrame(const Features& f, const Keyframe& reference,
                                     const std::optional<Eigen::Isometry3d>& guess,
                                     FrameTiming& timing) const {
  Attempt a;
  const auto t0 = Clock::now();
  const auto matches = matcher_.match(f.descriptors, reference.descriptors);
  timing.matching_ms += msSince(t0);
  a.matches = matches.size();
  if (static_cast<int>(matches.size()) < options_.pnp.min_inliers) return a;
  std::vector<Eigen::Vector3d> points;
  std::vector<Eigen::Vector2d> pixels;
  points.reserve(matches.size());
  pixels.reserve(matches.size());
  for (const auto& m : matches) {
    points.push_back(reference.points_world[static_cast<std::size_t>(m.trainIdx)]);
    const auto& pt = f.keypoints[static_cast<std::size_t>(m.queryIdx)].pt;
    pixels.emplace_back(pt.x, pt.y);
    a.keypoints.push_back(m.queryIdx);
    a.point_ids.push_back(reference.point_ids[static_cast<std::size_t>(m.trainIdx)]);
  }
  const auto t1 = Clock::now();
  std::optional<Eigen::Isometry3d> camera_from_world;
  if (guess) camera_from_world = guess->inverse();
  const std::vector<double> depths = measuredDepths(f, a.keypoints);
  a.estimate = estimator_.estimate(points, pixels, camera_from_world, &depths);
  timing.pnp_ms += msSince(t1);
  a.points = std::move(points);
  return a;
}

TrackResult Tracker::track(const RgbdFrame& frame) {
  const auto t0 = Clock::now();
  TrackResult r;
  r.frame = frame_counter_++;
  r.timestamp = frame.timestamp;
  r.camera_to_world = pose_;
  ++stats_.frames;
  const auto skip = [&](std::string reason) {
    r.state = TrackingState::kSkipped;
    r.skip_reason = std::move(reason);
    ++stats_.skipped;
    r.timing.total_ms = msSince(t0);
    return r;
  };
  if (std::string why = checkFrame(frame); !why.empty()) return skip(std::move(why));

  cv::Mat gray = frame.image;
  if (gray.type() == CV_8UC3) cv::cvtColor(frame.image, gray, cv::COLOR_RGB2GRAY);
  const auto te = Clock::now();
  const Features f = extractor_.extract(gray, frame.depth, frame.depth_scale);
  r.timing.extraction_ms = msSince(te);
  r.features = f.size();
  r.features_with_depth = f.with_depth;

  if (!initialised_) {
    if (static_cast<int>(f.with_depth) < options_.min_init_features)
      return skip("too few features with depth to start the map (" + std::to_string(f.with_depth) +
                  " < " + std::to_string(options_.min_init_features) + ")");
    initialised_ = true;
    pose_ = initial_pose_;
    keyframes_.push_back(makeKeyframe(f, pose_, r.frame, frame.timestamp, nullptr));
    held_.insert(keyframes_.size() - 1);
    keyframes_.back().id = 0;
    for (auto& id : keyframes_.back().point_ids) id = next_point_id_++;
    reference_keyframe_ = 0;
    previous_ = keyframes_.back();
    ++stats_.keyframes;
    r.state = TrackingState::kInitialised;
    r.camera_to_world = pose_;
    r.pose_valid = true;
    r.keyframe = true;
    r.decision = KeyframeDecision::kKeyframe;
    r.timing.total_ms = msSince(t0);
    return r;
  }

  const int min_inliers = options_.min_tracking_inliers;
  Attempt a;
  TrackingState state = TrackingState::kLost;
  if (!lost_) {
    const Eigen::Isometry3d predicted =
        options_.constant_velocity && has_velocity_ ? pose_ * velocity_ : pose_;
    a = trackLocalMap(f, predicted, r.timing);
    if (a.ok(min_inliers)) {
      state = TrackingState::kTracking;
    } else if (previous_) {
      a = trackFrame(f, *previous_, predicted, r.timing);
      if (a.ok(min_inliers)) state = TrackingState::kTrackingPrevious;
    }
  }
  if (state == TrackingState::kLost && !keyframes_.empty()) {
    // Relocalisation: newest keyframes first, spread over the whole map when there are more
    // than relocalisation_candidates.
    const std::size_t n = keyframes_.size();
    const std::size_t cands = static_cast<std::size_t>(options_.relocalisation_candidates);
    const std::size_t stride = (n + cands - 1) / cands;
    Attempt best;
    std::size_t best_kf = 0;
    for (std::size_t c = 0; c < cands && c * stride < n; ++c) {
      const std::size_t k = n - 1 - c * stride;
      if (keyframes_[k].points_world.empty()) continue;  // forgotten (lifelong mode)
      Attempt t = trackFrame(f, keyframes_[k], std::nullopt, r.timing);
      if (t.estimate.ok && t.estimate.inliers.size() > best.estimate.inliers.size()) {
        best = std::move(t);
        best_kf = k;
      }
    }
    if (best.ok(options_.relocalisation_min_inliers)) {
      a = std::move(best);
      state = TrackingState::kRelocalised;
      reference_keyframe_ = best_kf;
    }
  }

  if (state == TrackingState::kLost) {
    lost_ = true;
    has_velocity_ = false;
    ++stats_.lost;
    r.state = state;
    r.matches = a.matches;
    r.timing.total_ms = msSince(t0);
    return r;
  }

  const Eigen::Isometry3d pose = a.estimate.camera_from_world.inverse();
  // The velocity is only meaningful between consecutive tracked frames.
  has_velocity_ = state != TrackingState::kRelocalised;
  velocity_ = has_velocity_ ? pose_.inverse() * pose : Eigen::Isometry3d::Identity();
  pose_ = pose;
  lost_ = false;
  if (state == TrackingState::kTracking) ++stats_.tracked_local_map;
  if (state == TrackingState::kTrackingPrevious) ++stats_.tracked_previous;
  if (state == TrackingState::kRelocalised) ++stats_.relocalised;

  r.state = state;
  r.camera_to_world = pose_;
  r.pose_valid = true;
  r.matches = a.matches;
  r.inliers = static_cast<int>(a.estimate.inliers.size());
  r.reprojection_rms_px = a.estimate.rms_px;

  const Eigen::Isometry3d delta = keyframes_[reference_keyframe_].camera_to_world.inverse() * pose_;
  const KeyframeDecision decision = selector_.decide(r.inliers, delta);
  r.decision = decision;
  large_drops_ = decision == KeyframeDecision::kDropTooLarge ? large_drops_ + 1 : 0;
  const bool forced =
      options_.insert_after_large_drops > 0 && large_drops_ >= options_.insert_after_large_drops;
  Keyframe current = makeKeyframe(f, pose_, r.frame, frame.timestamp, &a);
  if ((decision == KeyframeDecision::kKeyframe || forced) &&
      static_cast<int>(current.points_world.size()) >= options_.min_init_features) {
    current.id = keyframes_.size();
    for (auto& id : current.point_ids)
      if (id < 0) id = next_point_id_++;
    keyframes_.push_back(current);
    held_.insert(keyframes_.size() - 1);
    reference_keyframe_ = keyframes_.size() - 1;
    ++stats_.keyframes;
    if (forced && decision != KeyframeDecision::kKeyframe) ++stats_.forced_keyframes;
    large_drops_ = 0;
    r.keyframe = true;
    if (options_.local_ba.keyframes > 0) {
      const auto tb = Clock::now();
      if (adjustLocalWindow(keyframes_, camera_, options_.local_ba).ran) {
        ++stats_.local_ba_runs;
        // This frame is the newest keyframe: it reports, and the next frame predicts from, the
        // adjusted pose.
        const Eigen::Isometry3d adjusted = keyframes_.back().camera_to_world;
        if (has_velocity_) velocity_ = velocity_ * pose_.inverse() * adjusted;
        pose_ = adjusted;
        r.camera_to_world = pose_;
        current = keyframes_.back();
      }
      r.timing.local_ba_ms = msSince(tb);
    }
  }
  previous_ = std::move(current);
  r.timing.total_ms = msSince(t0);
  return r;
}

bool Tracker::forgetKeyframe(std::size_t id) {
  // The newest keyframes stay: the local map and bundle adjustment (with its fixed ones) use them.
  const int adjusted = options_.local_ba.keyframes > 0
                           ? options_.local_ba.keyframes + options_.local_ba.fixed_keyframes
                           : 0;
  const auto recent = static_cast<std::size_t>(std::max(options_.local_map_keyframes, adjusted));
  if (!held_.contains(id) || id + recent >= keyframes_.size() || id == reference_keyframe_)
    return false;
  Keyframe& k = keyframes_[id];
  // Swapped with empty ones, so the memory goes, not just the sizes; the pose and the numbering
  // stay (ids are indices).
  std::vector<cv::KeyPoint>().swap(k.keypoints);
  k.descriptors = cv::Mat();
  std::vector<Eigen::Vector3d>().swap(k.points_camera);
  std::vector<Eigen::Vector3d>().swap(k.points_world);
  std::vector<std::int64_t>().swap(k.point_ids);
  held_.erase(id);
  ++forgotten_;
  return true;
}

}  // namespace tessera::visual_slam
