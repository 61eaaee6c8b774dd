// Tracker: RGB-D visual odometry against a local map of recent keyframes
// (docs/algorithms.md#rgb-d-visual-odometry).
//
// Per frame:
//   1. features (FeatureExtractor) with 3D points where the depth is good;
//   2. a constant-velocity prediction of the pose (the last inter-frame motion applied again);
//   3. tracking against the local map: the 3D points of the last local_map_keyframes keyframes,
//      and of up to local_map_nearby older keyframes whose pose is near the predicted one (the
//      keyframe rule's motion size e below local_map_nearby_motion, nearest first; so a view
//      seen before is tracked against the map made then, not only against recent drift), are
//      projected into the predicted view, and each is matched, by descriptor, to the
//      current keypoints within search_radius pixels (best below the distance limit and clearly
//      better than the second best, then one map point per keypoint); RANSAC PnP + refinement
//      (PoseEstimator) gives the pose;
//   4. if that has fewer than min_tracking_inliers, the previous frame instead: its features
//      with depth matched by FeatureMatcher (ratio test, minimum-distance filter), then PnP;
//   5. if that fails too, the frame is lost: its pose is the last good one (flagged invalid)
//      and every following frame tries to relocalise against the stored keyframes (descriptor
//      matching + PnP, up to relocalisation_candidates keyframes per frame, newest first) until
//      one gives relocalisation_min_inliers;
//   6. the keyframe rule (KeyframeSelector) on the motion since the last keyframe; a keyframe
//      stores the frame's features with their 3D points in the world (a feature that matched
//      a map point and agrees with it keeps that point's position and identity:
//      reuse_map_points); with local_ba_keyframes > 0, a local bundle adjustment then refines
//      the newest keyframes' poses and their points (local_bundle_adjustment.hpp), and the new
//      keyframe's frame reports its adjusted pose.
// The first frame with at least min_init_features 3D points starts the map at the identity pose
// (or at set_initial_pose); frames before it are skipped. A frame that cannot be used (empty
// image, wrong size or type, no depth before initialisation) is skipped and counted, never an
// exception; only bad options or intrinsics throw, from the constructor.
//
// Frames: poses are camera-to-world (x_world = T * x_camera), the camera in the optical
// convention (x right, y down, z forward); metres, seconds, milliseconds for timings.
// Not thread-safe: one caller at a time (extraction and the local-map search use TBB inside).
#pragma once

#include <tessera/visual_slam/camera.hpp>
#include <tessera/visual_slam/feature_extractor.hpp>
#include <tessera/visual_slam/feature_matcher.hpp>
#include <tessera/visual_slam/keyframe_selector.hpp>
#include <tessera/visual_slam/local_bundle_adjustment.hpp>
#include <tessera/visual_slam/pose_estimator.hpp>

#include <opencv2/core.hpp>

#include <Eigen/Geometry>

#include <cstddef>
#include <cstdint>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <vector>

namespace tessera::visual_slam {

struct TrackerOptions {
  FeatureExtractorOptions extractor;
  FeatureMatcherOptions matcher;
  PoseEstimatorOptions pnp;
  KeyframeOptions keyframes;
  LocalBundleAdjustmentOptions local_ba;
  int local_map_keyframes = 5;  ///< recent keyframes whose points form the local map
  int local_map_nearby = 10;    ///< plus at most this many older keyframes near the prediction
  double local_map_nearby_motion = 0.5;  ///< "near": motion size e below this [rad + m]
  double search_radius = 15;             ///< [px] around a projected map point
  /// Largest descriptor distance of a local-map match; 0 = by descriptor: 64 bits (ORB), 250
  /// (SIFT).
  double local_map_max_distance = 0;
  double local_map_ratio = 0.9;   ///< best < ratio x second best among nearby keypoints
  int min_tracking_inliers = 20;  ///< fewer: try the next fallback / lost
  int min_init_features = 50;     ///< 3D points needed to start the map
  int relocalisation_min_inliers = 30;
  int relocalisation_candidates = 20;  ///< keyframes tried per lost frame
  /// After this many consecutive well-tracked frames that the rule drops as "too large" (which
  /// it does when the map lagged behind, e.g. through frames without depth), one becomes a
  /// keyframe anyway so the local map follows the camera. 0 = never.
  int insert_after_large_drops = 5;
  bool constant_velocity = true;
  /// A new keyframe's feature that matched a map point (a PnP inlier whose own depth agrees
  /// within the depth-edge tolerance) keeps that point's position instead of its own
  /// measurement, so the map is not re-anchored to the drifting pose at every keyframe.
  bool reuse_map_points = true;
  /// Colour and depth that are not registered (7-Scenes): track the colour camera with the
  /// depth re-projected into it (depth_registration.hpp), and report poses of the depth camera.
  /// The Tracker itself never registers; its callers (the rgbd_front_end actor, `bench rgbd`)
  /// decide through depthRegistration(), so this is the one default for both.
  bool register_depth = true;

  template <class V>
  void visit(V& v) {
    extractor.visit(v);
    matcher.visit(v);
    pnp.visit(v);
    keyframes.visit(v);
    local_ba.visit(v);
    v("local_map_keyframes", local_map_keyframes, "recent keyframes forming the local map");
    v("local_map_nearby", local_map_nearby,
      "older keyframes near the predicted pose added to the local map");
    v("local_map_nearby_motion", local_map_nearby_motion,
      "an older keyframe is near when the motion size to it is below this [rad + m]");
    v("search_radius", search_radius, "search radius around a projected map point [px]");
    v("local_map_max_distance", local_map_max_distance,
      "largest descriptor distance of a local-map match (0 = 64 for ORB, 250 for SIFT)");
    v("local_map_ratio", local_map_ratio, "local-map ratio test among nearby keypoints");
    v("min_tracking_inliers", min_tracking_inliers, "fewest PnP inliers to accept tracking");
    v("min_init_features", min_init_features, "3D points needed to start the map");
    v("relocalisation_min_inliers", relocalisation_min_inliers,
      "fewest PnP inliers to accept a relocalisation");
    v("relocalisation_candidates", relocalisation_candidates, "keyframes tried per lost frame");
    v("insert_after_large_drops", insert_after_large_drops,
      "consecutive too-large drops after which a tracked frame becomes a keyframe (0 = never)");
    v("constant_velocity", constant_velocity, "predict with the last inter-frame motion");
    v("reuse_map_points", reuse_map_points,
      "a keyframe keeps the positions of the map points its features matched");
    v("register_depth", register_depth,
      "unregistered colour and depth (7-Scenes): re-project depth into the colour camera");
  }
  /// Throws std::invalid_argument naming the first bad option (also of the nested groups).
  void validate() const;
};

/// A keyframe (or the previous frame): the features that have a 3D point.
struct Keyframe {
  std::size_t id = 0;     ///< 0, 1, ... in insertion order
  std::size_t frame = 0;  ///< index of the frame it was made from
  double timestamp = 0;   ///< [s]
  Eigen::Isometry3d camera_to_world = Eigen::Isometry3d::Identity();
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;
  std::vector<Eigen::Vector3d> points_camera;  ///< [m]
  std::vector<Eigen::Vector3d> points_world;   ///< [m]
  /// Per feature: the map point it is (shared by the keyframes that matched it; -1 = not a
  /// keyframe's point yet). Local bundle adjustment moves every copy of a point together.
  std::vector<std::int64_t> point_ids;
};

enum class TrackingState {
  kSkipped,           ///< unusable frame (see TrackResult::skip_reason)
  kInitialised,       ///< the first keyframe
  kTracking,          ///< tracked against the local map
  kTrackingPrevious,  ///< tracked against the previous frame (local map too weak)
  kRelocalised,       ///< found again against a stored keyframe
  kLost,
};
std::string_view stateName(TrackingState s);

/// Wall time of one frame's stages [ms]. local_map: projecting the local map and searching it
/// (its descriptor comparisons included); matching: brute-force matching (previous frame,
/// relocalisation); pnp: RANSAC PnP and refinement; local_ba: local bundle adjustment (keyframes
/// only).
struct FrameTiming {
  double extraction_ms = 0, local_map_ms = 0, matching_ms = 0, pnp_ms = 0, local_ba_ms = 0,
         total_ms = 0;
};

struct TrackResult {
  std::size_t frame = 0;  ///< 0, 1, ... in call order
  double timestamp = 0;
  TrackingState state = TrackingState::kSkipped;
  std::string skip_reason;
  /// Always finite. Lost or skipped: the last good pose, and pose_valid is false.
  Eigen::Isometry3d camera_to_world = Eigen::Isometry3d::Identity();
  bool pose_valid = false;
  std::optional<KeyframeDecision> decision;  ///< tracked frames only
  bool keyframe = false;                     ///< a keyframe was inserted from this frame
  std::size_t features = 0, features_with_depth = 0;
  std::size_t matches = 0;  ///< correspondences given to PnP by the stage that succeeded
  int inliers = 0;
  double reprojection_rms_px = 0;
  FrameTiming timing;
};

struct TrackerStats {
  std::size_t frames = 0, skipped = 0, tracked_local_map = 0, tracked_previous = 0, relocalised = 0,
              lost = 0, keyframes = 0, forced_keyframes = 0, local_ba_runs = 0;
};

class Tracker {
 public:
  /// Throws std::invalid_argument for bad options or intrinsics.
  Tracker(const TrackerOptions& options, const PinholeCamera& camera);

  /// Where the map starts (before the first frame; default identity).
  void setInitialPose(const Eigen::Isometry3d& camera_to_world) { initial_pose_ = camera_to_world; }

  TrackResult track(const RgbdFrame& frame);

  /// Lifelong mode: releases keyframe `id`'s features and points (the keyframe graph trimmed it;
  /// a newer keyframe covers its place), keeping its pose and number. It is no longer in a local
  /// map or a relocalisation candidate. False for an unknown or already forgotten id, one of the
  /// newest (local map, bundle adjustment window) or the current reference keyframe.
  bool forgetKeyframe(std::size_t id);
  std::size_t forgottenKeyframes() const { return forgotten_; }
  /// The ids of the keyframes not forgotten, ascending: what forgetKeyframe may still release.
  const std::set<std::size_t>& heldKeyframes() const { return held_; }

  const std::vector<Keyframe>& keyframes() const { return keyframes_; }
  const TrackerStats& stats() const { return stats_; }
  const KeyframeCounts& keyframeCounts() const { return selector_.counts(); }
  const TrackerOptions& options() const { return options_; }

 private:
  struct Attempt;
  Attempt trackLocalMap(const Features& f, const Eigen::Isometry3d& predicted,
                        FrameTiming& timing) const;
  Attempt trackFrame(const Features& f, const Keyframe& reference,
                     const std::optional<Eigen::Isometry3d>& guess, FrameTiming& timing) const;
  /// `tracked`: the attempt that gave the pose; its inliers keep their map points.
  Keyframe makeKeyframe(const Features& f, const Eigen::Isometry3d& camera_to_world,
                        std::size_t frame, double timestamp, const Attempt* tracked) const;
  std::string checkFrame(const RgbdFrame& frame) const;

  TrackerOptions options_;
  PinholeCamera camera_;
  FeatureExtractor extractor_;
  FeatureMatcher matcher_;
  PoseEstimator estimator_;
  KeyframeSelector selector_;

  Eigen::Isometry3d initial_pose_ = Eigen::Isometry3d::Identity();
  bool initialised_ = false, lost_ = false, has_velocity_ = false;
  Eigen::Isometry3d pose_ = Eigen::Isometry3d::Identity();      ///< last good camera-to-world
  Eigen::Isometry3d velocity_ = Eigen::Isometry3d::Identity();  ///< last inter-frame motion
  std::size_t reference_keyframe_ = 0;  ///< the rule measures motion from this keyframe
  int large_drops_ = 0;
  std::optional<Keyframe> previous_;  ///< the last tracked frame
  std::vector<Keyframe> keyframes_;
  std::size_t frame_counter_ = 0;
  std::int64_t next_point_id_ = 0;
  std::size_t forgotten_ = 0;
  std::set<std::size_t> held_;  ///< keyframes not forgotten
  TrackerStats stats_;
};

}  // namespace tessera::visual_slam
