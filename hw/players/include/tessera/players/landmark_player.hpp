// LandmarkPlayer ("landmark_player"): replays a point-landmark dataset on the runtime clock as a
// finite source. The whole dataset is read and checked in the constructor (errors become a
// ConfigError naming the option and the file:line), then one-shot callAt timers chain from one
// dataset time to the next; everything due at one time is published in one callback.
//
// Time: stamps are the runtime time at configure() plus the dataset time since its first record
// (MRCLAM: the earliest odometry/measurement/ground-truth time; relative times are rounded to
// whole microseconds, the files have 1 ms resolution). Victoria Park has no timestamps: pose k
// is played at k * victoria_step_s (default 0.2 s, near the original 5 Hz laser; NOT a
// recorded time, so velocities derived from it are nominal).
//
// Publishes (local topic names). At equal stamps the order is landmark_map, ground_truth, odom,
// landmarks, robots, control, so a filter sees the sightings at t before the control that
// starts at t.
//   control       msg::DriveControl  frame base_link; a differential-drive control (steering 0,
//                 wheelbase 0) holding over [stamp, stamp + dtS).
//                   MRCLAM: the odometry row (speed = v, turnRate = omega), dtS = time to the
//                   next row (0 for the last).
//                   Victoria: odometry k -> k+1 over one step: turnRate = dtheta / step, speed =
//                   the length of the constant-curvature arc whose chord is (dx, dy), / step
//                   (negative when dx < 0). The arc explains dx, dy only up to the sideways
//                   slip the file records; the exact increment is in `odom`.
//   odom          msg::Odometry      Victoria only: frame odom, child base_link; pose k = the
//                 file's increments composed from the origin (exact); twist = the control that
//                 led to it, twistCovariance = the increment covariance / step^2; pose
//                 covariance empty (unknown).
//   landmarks     msg::LandmarkScan  frame camera (MRCLAM) / laser (Victoria), mount = identity
//                 (both datasets give range-bearing from the robot centre). Observation id = the
//                 dense landmark index (MRCLAM: row of Landmark_Groundtruth.dat; Victoria: rank
//                 of the landmark id). Published only at times with at least one landmark
//                 sighting. Stds: MRCLAM from the range_std / bearing_std options (0 = unknown);
//                 Victoria from the file (see landmark_logs.hpp).
//   robots        msg::LandmarkScan  MRCLAM only: sightings of other robots, id = robot subject
//                 number (1..5). Kept off `landmarks` so landmark SLAM never maps a moving robot.
//   landmark_map  msg::LandmarkMap   MRCLAM only, once at the first stamp: ground-truth landmarks,
//                 frame map, id = landmark index, covariance diag(std_x^2, std_y^2).
//   ground_truth  msg::GroundTruthPose  MRCLAM only, and only if RobotN_Groundtruth.dat(.gz)
//                 exists (it is absent from the shared copy of dataset 1): frame map.
#pragma once

#include <tessera/msg/landmark.capnp.h>
#include <tessera/datasets/landmark_logs.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace tessera::players {

struct LandmarkPlayerOptions {
  std::string format = "mrclam";
  std::string path;
  int robot = 1;
  double victoria_step_s = 0.2;
  double range_std = 0;
  double bearing_std = 0;

  template <class V>
  void visit(V& v) {
    v("format", format, "'mrclam' (UTIAS MRCLAM folder) or 'victoria' (GTSAM victoria_park.txt)");
    v("path", path,
      "mrclam: the dataset folder (Barcodes.dat, Landmark_Groundtruth.dat, RobotN_*.dat[.gz]); "
      "victoria: the text file. Relative paths from the working directory");
    v("robot", robot, "mrclam: which robot to play, 1..5");
    v("victoria_step_s", victoria_step_s,
      "victoria: time between poses [s] (the file has no timestamps), in (0, 10]");
    v("range_std", range_std, "mrclam: range 1-sigma put in observations [m] (0 = unknown)");
    v("bearing_std", bearing_std,
      "mrclam: bearing 1-sigma put in observations [rad] (0 = unknown)");
  }
};

class LandmarkPlayerActor final : public Actor {
 public:
  /// Reads the dataset; throws ConfigError for bad options or an unreadable/malformed dataset.
  explicit LandmarkPlayerActor(LandmarkPlayerOptions options);

  void configure(ActorContext& ctx) override;
  /// events, controls_published, scans_published, observations_published,
  /// robot_scans_published, odom_published, ground_truth_published, data_duration_s,
  /// lines_skipped.
  void summarize(Summary& out) const override;

  /// Messages the whole dataset will publish (all topics); for tests and progress.
  std::size_t eventCount() const { return events_.size(); }

 private:
  enum class Kind : std::uint8_t { kMap, kGroundTruth, kOdom, kLandmarks, kRobots, kControl };
  struct Event {
    Nanos time;  // since the first record
    Kind kind;
    std::uint32_t index;  // row / group / pose, by kind
  };
  struct Group {  // consecutive rows with one time (MRCLAM measurements, Victoria sightings)
    std::size_t begin, end;
  };

  void buildMrclam();
  void buildVictoria();
  void play();
  void publish(const Event& e, Nanos stamp);
  void publishScan(const Group& g, bool robots, Nanos stamp);

  LandmarkPlayerOptions options_;
  std::optional<datasets::MrclamRobotLog> mrclam_;
  std::optional<datasets::VictoriaParkLog> victoria_;
  std::vector<std::size_t> victoria_order_;     // sightings sorted by pose
  std::vector<tessera::Pose2> victoria_poses_;  // integrated odometry, pose k
  std::vector<Group> groups_;
  std::vector<Event> events_;
  Nanos step_ = 0;

  ActorContext* ctx_ = nullptr;
  Nanos base_ = 0;
  std::size_t next_ = 0;
  Publisher<msg::DriveControl> control_pub_;
  Publisher<msg::Odometry> odom_pub_;
  Publisher<msg::LandmarkScan> landmarks_pub_, robots_pub_;
  Publisher<msg::LandmarkMap> map_pub_;
  Publisher<msg::GroundTruthPose> gt_pub_;

  std::int64_t controls_ = 0, scans_ = 0, observations_ = 0, robot_scans_ = 0, odoms_ = 0,
               ground_truth_ = 0;
};

}  // namespace tessera::players
