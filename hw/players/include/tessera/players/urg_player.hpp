// urg_player: replays a MinesParisTech / BreezySLAM URG-04LX log (tessera/datasets/urg_log.hpp)
// as laser scans and wheel odometry on the simulated clock. A finite source.
//
// Publishes (local topic names), for each line of the log, odom first:
//   odom  msg::Odometry   frame "odom", child "base_link": the encoder counts dead-reckoned with
//                         the differential-drive model (wheel_radius, half_axle,
//                         ticks_per_revolution); starts at (0, 0, 0); twist from the increment
//   scan  msg::LaserScan  frame "laser": 682 beams over fov_deg, counter-clockwise; +inf = no
//                         return (reading 0), NaN = Hokuyo error code; mount from laser_mount
//                         (145 mm ahead of the axle on the MinesParisTech robot); not with
//                         publish_scans false
//
// Time: as carmen_player (replay.hpp): line k at runtime_start + (t_k - t_0); stamps are the
// log's own microsecond timestamps in ns (they count from the robot's boot, ~361 s on exp2),
// or runtime time with relative_stamps. A malformed line mid-run stops the run with its
// file:line reason unless skip_malformed.
#pragma once

#include <tessera/datasets/urg_log.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/players/replay.hpp>
#include <tessera/runtime/actor.hpp>

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace tessera::players {

struct UrgPlayerOptions {
  std::string path;
  double wheel_radius = 0.077;
  double half_axle = 0.165;
  double ticks_per_revolution = 2000;
  std::vector<double> laser_mount = {0.145, 0, 0};
  double fov_deg = 240;
  double min_range = 0.02;
  double max_range = 5.6;
  bool zero_is_no_return = true;
  double start_time = 0;
  double end_time = 0;
  std::int64_t max_scans = 0;
  bool relative_stamps = false;
  bool skip_malformed = false;
  bool publish_scans = true;
  bool urg04lx_steps = false;

  template <class V>
  void visit(V& v) {
    v("path", path, "URG log such as exp2.dat(.gz); required, e.g. --set player.path=FILE");
    v("wheel_radius", wheel_radius, "odometry wheel radius [m] (MinesParisTech robot: 0.077)");
    v("half_axle", half_axle, "half the distance between the wheels [m] (0.165)");
    v("ticks_per_revolution", ticks_per_revolution,
      "encoder counts per wheel revolution (2000: BreezySLAM's model, confirmed by the laser)");
    v("laser_mount", laser_mount, "laser pose in base_link [x m, y m, theta rad]");
    v("fov_deg", fov_deg, "angle spanned by the beams, first to last [deg]");
    v("min_range", min_range, "range_min of the scans [m]");
    v("max_range", max_range, "range_max of the scans [m] (URG-04LX: 5.6)");
    v("zero_is_no_return", zero_is_no_return,
      "readings of 0 are no return (+inf); false: invalid (NaN)");
    v("start_time", start_time, "skip lines earlier than this [s after the first line]");
    v("end_time", end_time, "stop after this time [s after the first line]; 0 = the end");
    v("max_scans", max_scans, "stop after this many scans; 0 = all");
    v("relative_stamps", relative_stamps,
      "stamp messages with runtime time (0 at the first line) instead of the log's time");
    v("skip_malformed", skip_malformed, "skip and count malformed lines instead of stopping");
    v("publish_scans", publish_scans,
      "publish the scans; false: odometry only (the scans come from a driver, e.g. hokuyo_scip on "
      "`tessera emulate scip` streaming the same log)");
    v("urg04lx_steps", urg04lx_steps,
      "beam angles of the URG-04LX's own steps 44..725 (1024 per turn, step 384 ahead), as its "
      "SCIP driver reports them, instead of fov_deg spread evenly");
  }
};

class UrgPlayer final : public Actor {
 public:
  explicit UrgPlayer(UrgPlayerOptions options);  // throws ConfigError

  void configure(ActorContext& ctx) override;
  // records_read, scans_published, odom_published, lines_skipped, distance_m (odometry path
  // length), first_stamp_s, last_stamp_s, time_reversals, error.
  void summarize(Summary& out) const override;

 private:
  struct Pending {
    datasets::UrgScan scan;
    Nanos stamp = 0;
  };
  void step();
  bool readNext();
  void publish(const Pending& p);
  void finish(const std::string& error);

  UrgPlayerOptions options_;
  datasets::UrgOptions parse_options_;
  datasets::DifferentialDriveModel model_;
  Pose2 mount_;

  ActorContext* ctx_ = nullptr;
  std::unique_ptr<datasets::UrgReader> reader_;
  Publisher<msg::LaserScan> scan_pub_;
  Publisher<msg::Odometry> odom_pub_;

  ReplayState<Pending> replay_;
  std::optional<Nanos> first_record_;
  // Odometry integrates over every line read, published or not, so start_time keeps the frame.
  std::optional<datasets::UrgScan> last_ticks_;
  tessera::Pose2 pose_;
  datasets::DriveIncrement last_increment_;
  double last_dt_ = 0;
  double distance_ = 0;
  bool done_ = false;

  std::int64_t scans_ = 0, odom_ = 0;
  std::optional<Nanos> first_stamp_, last_stamp_;
  std::string error_;
  io::ParseReport final_report_;
};

}  // namespace tessera::players
