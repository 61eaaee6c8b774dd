// carmen_player: replays a CARMEN laser log (FLASER, RLASER, ROBOTLASER1, RAWLASERn, ODOM; see
// tessera/datasets/carmen_log.hpp) as messages on the simulated clock. A finite source.
//
// Publishes (local topic names):
//   scan          msg::LaserScan        frame "laser"; one laser message type of the log
//                                       (`laser`); +inf = no return; mount from `laser_mount`
//   odom          msg::Odometry         frame "odom", child "base_link" (`odometry` source)
//   ground_truth  msg::GroundTruthPose  frame "map" (only with publish_reference): the laser
//                                       lines' x y theta moved from the laser to base_link. Use
//                                       it with GMapping-corrected logs (*.gfs, *-corrected),
//                                       whose laser poses are the corrected trajectory; it is
//                                       a reference estimate, not independent ground truth.
// At equal stamps, odom and ground_truth are published before the scan, so a known-pose consumer
// can pair them exactly.
//
// Time: each record is published at runtime_start + (t - t_first) via ctx.callAt (so the run
// goes as fast as consumers allow, or at the profile's sim_rate); stamps are the log's absolute
// ipc_timestamps in ns, rounded to µs (see replay.hpp), unless relative_stamps. Records whose
// time goes backwards are published at once, with their own stamps, and counted.
//
// Errors: bad options throw ConfigError (a missing `path` names the option); a malformed line
// or a truncated file mid-run stops the run (ctx.requestStop) with the file:line reason, or,
// with skip_malformed, is skipped and counted.
#pragma once

#include <tessera/datasets/carmen_log.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/players/replay.hpp>
#include <tessera/runtime/actor.hpp>

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace tessera::players {

struct CarmenPlayerOptions {
  std::string path;
  std::string laser = "auto";
  std::string odometry = "auto";
  bool publish_reference = false;
  double max_range = 80.0;
  double min_range = 0.0;
  std::vector<double> laser_mount = {0, 0, 0};
  double start_time = 0;
  double end_time = 0;
  std::int64_t max_scans = 0;
  bool relative_stamps = false;
  bool skip_malformed = false;
  std::string scan_times;

  template <class V>
  void visit(V& v) {
    v("path", path, "CARMEN log (plain or gzip); required, e.g. --set player.path=FILE");
    v("laser", laser,
      "laser message to publish on 'scan': FLASER | RLASER | ROBOTLASER1 | RAWLASER1..4 | "
      "auto (the first laser message of the log)");
    v("odometry", odometry,
      "pose source for 'odom': odom (ODOM lines) | laser (the laser lines' odometry pose) | "
      "none | auto (ODOM lines when the log has any, else the laser lines')");
    v("publish_reference", publish_reference,
      "also publish the laser lines' x y theta on 'ground_truth' (for GMapping-corrected logs)");
    v("max_range", max_range,
      "FLASER/RLASER readings >= this [m] are no return (+inf); SICK logs use 81.83/81.91 for "
      "it. ROBOTLASER1/RAWLASER use their own max_range field");
    v("min_range", min_range, "range_min of the scans [m]: shorter readings are invalid");
    v("laser_mount", laser_mount, "laser pose in base_link [x m, y m, theta rad]");
    v("start_time", start_time, "skip records earlier than this [s after the first record]");
    v("end_time", end_time, "stop after this time [s after the first record]; 0 = the end");
    v("max_scans", max_scans, "stop after this many scans; 0 = all");
    v("relative_stamps", relative_stamps,
      "stamp messages with runtime time (0 at the first record) instead of the log's time");
    v("skip_malformed", skip_malformed,
      "skip and count malformed lines instead of stopping the run");
    v("scan_times", scan_times,
      "file of per-scan times `index seconds [flag]`, one line per laser line of the log in "
      "order, replacing the laser lines' own stamps (e.g. intel-lab-mrpt/frame_times.txt, "
      "whose log repeats stamps); empty = the log's stamps");
  }
};

class CarmenPlayer final : public Actor {
 public:
  // Checks the options and that the file opens; finds the laser type and odometry source
  // (one pass over the file head, or over the whole file when it has no ODOM line).
  explicit CarmenPlayer(CarmenPlayerOptions options);

  void configure(ActorContext& ctx) override;
  // records_read, scans_published, odom_published, reference_published, lines_skipped,
  // records_ignored, time_reversals, first_stamp_s, last_stamp_s, laser, odometry_source,
  // skipped (per message name), error ("" when the file was read to the end or the limits).
  void summarize(Summary& out) const override;

  const std::string& laserMessage() const { return laser_; }
  const std::string& odometrySource() const { return odometry_; }

 private:
  struct Pending {
    datasets::CarmenRecord record;
    Nanos stamp = 0;  // dataset time [ns]
  };
  void step();
  // Reads until a record this player publishes; false at the end (or the limits).
  bool readNext();
  void publish(const Pending& p);
  void finish(const std::string& error);

  CarmenPlayerOptions options_;
  datasets::CarmenOptions parse_options_;
  std::string laser_, odometry_;
  Pose2 mount_;
  std::vector<Nanos> scan_times_;  // from options_.scan_times, one per laser line
  std::size_t laser_lines_ = 0;    // laser lines of the chosen type read so far

  ActorContext* ctx_ = nullptr;
  std::unique_ptr<datasets::CarmenReader> reader_;
  Publisher<msg::LaserScan> scan_pub_;
  Publisher<msg::Odometry> odom_pub_;
  Publisher<msg::GroundTruthPose> gt_pub_;

  ReplayState<Pending> replay_;
  std::optional<Nanos> first_record_;  // dataset time of the first record read
  std::optional<Pose2> last_odom_pose_;
  Nanos last_odom_stamp_ = 0;
  bool done_ = false;

  std::int64_t scans_ = 0, odom_ = 0, reference_ = 0, ignored_ = 0;
  std::optional<Nanos> first_stamp_, last_stamp_;
  std::string error_;
  io::ParseReport final_report_;
};

}  // namespace tessera::players
