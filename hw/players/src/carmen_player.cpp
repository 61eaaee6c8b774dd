#include <tessera/players/carmen_player.hpp>

#include <tessera/messages/views.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/registry.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <sstream>

namespace tessera::players {
namespace {

[[noreturn]] void fail(const std::string& key, const std::string& what) {
  throw ConfigError("carmen_player: option '" + key + "': " + what);
}

bool isLaserMessage(std::string_view name) {
  return name == "FLASER" || name == "RLASER" || name == "ROBOTLASER1" || name == "RAWLASER1" ||
         name == "RAWLASER2" || name == "RAWLASER3" || name == "RAWLASER4";
}

// First laser message name and whether any ODOM line exists, from the line heads only. Stops as
// soon as both are known; a read error ends the scan quietly (the replay will report it where
// it happens).
void prescan(const std::filesystem::path& path, std::string& first_laser, bool& has_odom) {
  try {
    io::TextReader reader(path);
    std::string line;
    while ((first_laser.empty() || !has_odom) && reader.next(line)) {
      const auto begin = line.find_first_not_of(" \t");
      if (begin == std::string::npos) continue;
      const auto end = line.find_first_of(" \t", begin);
      const std::string_view name =
          std::string_view(line).substr(begin, end == std::string::npos ? end : end - begin);
      if (name == "ODOM") has_odom = true;
      if (first_laser.empty() && isLaserMessage(name)) first_laser = std::string(name);
    }
  } catch (const io::DatasetError&) {
  }
}

// `index seconds [flag]` per line, indices 0, 1, 2, ... in order, times strictly increasing.
std::vector<Nanos> readScanTimes(const std::string& path) {
  std::vector<Nanos> out;
  try {
    io::TextReader reader(path);
    std::string line;
    while (reader.next(line)) {
      const io::Fields f(reader, line);
      if (f.empty() || f[0].front() == '#') continue;
      if (f.size() < 2 || f.size() > 3)
        reader.fail("expected `index seconds [flag]`, got " + std::to_string(f.size()) + " fields");
      if (f.integer(0, "index") != static_cast<std::int64_t>(out.size()))
        reader.fail("index " + std::string(f[0]) + " out of order, expected " +
                    std::to_string(out.size()));
      const auto stamp = datasetSecondsToNanos(f.real(1, "seconds"));
      if (!stamp || (!out.empty() && *stamp <= out.back()))
        reader.fail("time " + std::string(f[1]) + " is not after the previous one");
      out.push_back(*stamp);
    }
  } catch (const io::DatasetError& e) {
    fail("scan_times", e.what());
  }
  if (out.empty()) fail("scan_times", "'" + path + "' holds no times");
  return out;
}

double recordTime(const datasets::CarmenRecord& r) {
  return std::visit([](const auto& x) { return x.timestamp; }, r);
}

}  // namespace

CarmenPlayer::CarmenPlayer(CarmenPlayerOptions options) : options_(std::move(options)) {
  const auto& o = options_;
  if (o.path.empty())
    fail("path", "is required: the CARMEN log to replay, e.g. --set player.path=FILE.clf.gz");
  std::error_code ec;
  if (!std::filesystem::is_regular_file(o.path, ec))
    fail("path", "'" + o.path + "' is not a readable file");
  if (!(o.max_range >= 0) || !std::isfinite(o.max_range))
    fail("max_range", "must be >= 0 and finite (0: keep every reading)");
  if (!(o.min_range >= 0) || !std::isfinite(o.min_range)) fail("min_range", "must be >= 0");
  if (o.laser_mount.size() != 3 || !std::all_of(o.laser_mount.begin(), o.laser_mount.end(),
                                                [](double v) { return std::isfinite(v); }))
    fail("laser_mount", "needs 3 finite values [x, y, theta]");
  if (!(o.start_time >= 0) || !std::isfinite(o.start_time)) fail("start_time", "must be >= 0");
  if (!(o.end_time >= 0) || !std::isfinite(o.end_time)) fail("end_time", "must be >= 0");
  if (o.end_time > 0 && o.end_time < o.start_time) fail("end_time", "is before start_time");
  if (o.max_scans < 0) fail("max_scans", "must be >= 0");
  if (o.laser != "auto" && !isLaserMessage(o.laser))
    fail("laser",
         "expected FLASER, RLASER, ROBOTLASER1, RAWLASER1..4 or auto, got '" + o.laser + "'");
  if (o.odometry != "auto" && o.odometry != "odom" && o.odometry != "laser" && o.odometry != "none")
    fail("odometry", "expected auto, odom, laser or none, got '" + o.odometry + "'");
  mount_ = {o.laser_mount[0], o.laser_mount[1], o.laser_mount[2]};
  if (!o.scan_times.empty()) scan_times_ = readScanTimes(o.scan_times);

  parse_options_.flaser_max_range = o.max_range;
  parse_options_.skip_malformed = o.skip_malformed;

  std::string first_laser;
  bool has_odom = false;
  if (o.laser == "auto" || o.odometry == "auto") prescan(o.path, first_laser, has_odom);
  laser_ = o.laser == "auto" ? (first_laser.empty() ? "FLASER" : first_laser) : o.laser;
  odometry_ = o.odometry == "auto" ? (has_odom ? "odom" : "laser") : o.odometry;
}

void CarmenPlayer::configure(ActorContext& ctx) {
  ctx_ = &ctx;
  ctx.declareFiniteSource();
  scan_pub_ = ctx.advertise<msg::LaserScan>("scan");
  if (odometry_ != "none") odom_pub_ = ctx.advertise<msg::Odometry>("odom");
  if (options_.publish_reference) gt_pub_ = ctx.advertise<msg::GroundTruthPose>("ground_truth");
  ctx.callAt(ctx.now(), [this] { step(); });
}

bool CarmenPlayer::readNext() {
  if (!reader_) reader_ = std::make_unique<datasets::CarmenReader>(options_.path, parse_options_);
  datasets::CarmenRecord record;
  while (reader_->next(record)) {
    const auto stamp = datasetSecondsToNanos(recordTime(record));
    if (!stamp)
      throw io::DatasetError(options_.path, 0,
                             "record " + std::to_string(reader_->report().records) +
                                 ": timestamp outside the representable range");
    if (!first_record_) first_record_ = *stamp;
    const double since_first = nanosToSeconds(*stamp - *first_record_);
    if (options_.end_time > 0 && since_first > options_.end_time) return false;
    bool wanted = false;
    Nanos publish_stamp = *stamp;
    if (const auto* l = std::get_if<datasets::CarmenLaser>(&record)) {
      wanted = l->message == laser_;
      if (wanted && !scan_times_.empty()) {
        if (laser_lines_ >= scan_times_.size())
          throw io::DatasetError(options_.scan_times, 0,
                                 "has " + std::to_string(scan_times_.size()) +
                                     " times but the log has more " + laser_ + " lines");
        publish_stamp = scan_times_[laser_lines_];
      }
      if (wanted) ++laser_lines_;
    } else {
      wanted = odometry_ == "odom";
    }
    if (!wanted || (options_.start_time > 0 && since_first < options_.start_time)) {
      ++ignored_;
      continue;
    }
    replay_.next = Pending{std::move(record), publish_stamp};
    return true;
  }
  return false;
}

void CarmenPlayer::step() {
  if (done_) return;
  try {
    const auto next_step = replay_.advance(
        ctx_->now(), [this] { return readNext(); }, [this](const Pending& p) { publish(p); },
        [this] { return options_.max_scans > 0 && scans_ >= options_.max_scans; });
    if (!next_step) return finish("");
    ctx_->reportProgress(reader_->progress());
    ctx_->callAt(*next_step, [this] { step(); });
  } catch (const std::exception& e) {
    finish(e.what());
  }
}

void CarmenPlayer::publish(const Pending& p) {
  const Nanos stamp = replay_.timeline.stamp(p.stamp, options_.relative_stamps);
  if (!first_stamp_) first_stamp_ = stamp;
  last_stamp_ = stamp;
  auto publishOdom = [&](const datasets::CarmenPose& pose, const BodyVelocity* twist) {
    const Pose2 now{pose.x, pose.y, pose.theta};
    BodyVelocity v;
    if (twist)
      v = *twist;
    else if (last_odom_pose_)
      v = bodyVelocity(*last_odom_pose_, now, nanosToSeconds(stamp - last_odom_stamp_));
    last_odom_pose_ = now;
    last_odom_stamp_ = stamp;
    auto loan = odom_pub_.loan();
    auto b = loan.builder();
    setHeader(b.initHeader(), stamp, "odom", odom_pub_.nextSeq());
    b.setChildFrameId("base_link");
    writePose(b.initPose(), tessera::Pose2{pose.x, pose.y, pose.theta});
    auto t = b.initTwist();
    t.setVx(v.vx);
    t.setVy(v.vy);
    t.setOmega(v.omega);
    odom_pub_.publish(std::move(loan));
    ++odom_;
  };

  if (const auto* o = std::get_if<datasets::CarmenOdometry>(&p.record)) {
    const BodyVelocity v{o->tv, 0, o->rv};
    publishOdom(o->pose, &v);
    return;
  }
  const auto& l = std::get<datasets::CarmenLaser>(p.record);
  if (l.has_pose && odometry_ == "laser") publishOdom(l.robot_pose, nullptr);
  if (l.has_pose && options_.publish_reference) {
    const Pose2 base = Pose2{l.laser_pose.x, l.laser_pose.y, l.laser_pose.theta} * mount_.inverse();
    auto loan = gt_pub_.loan();
    auto b = loan.builder();
    setHeader(b.initHeader(), stamp, "map", gt_pub_.nextSeq());
    writePose(b.initPose(), tessera::Pose2{base.x, base.y, base.theta});
    b.setChildFrameId("base_link");
    gt_pub_.publish(std::move(loan));
    ++reference_;
  }
  auto loan = scan_pub_.loan(l.ranges.size() * 2 * sizeof(float) + 256);
  auto b = loan.builder();
  setHeader(b.initHeader(), stamp, "laser", scan_pub_.nextSeq());
  b.setAngleMin(l.angle_min);
  b.setAngleIncrement(l.angle_increment);
  b.setRangeMin(static_cast<float>(options_.min_range));
  b.setRangeMax(l.max_range);
  b.setScanTimeS(0.0f);
  b.setMountX(static_cast<float>(mount_.x));
  b.setMountY(static_cast<float>(mount_.y));
  b.setMountTheta(static_cast<float>(mount_.theta));
  auto ranges = mutableView<float>(b.initRanges(static_cast<unsigned>(l.ranges.size())));
  std::copy(l.ranges.begin(), l.ranges.end(), ranges.begin());
  if (!l.remissions.empty() && l.remissions.size() == l.ranges.size()) {
    auto intensities =
        mutableView<float>(b.initIntensities(static_cast<unsigned>(l.remissions.size())));
    std::copy(l.remissions.begin(), l.remissions.end(), intensities.begin());
  }
  scan_pub_.publish(std::move(loan));
  ++scans_;
}

void CarmenPlayer::finish(const std::string& error) {
  if (done_) return;
  done_ = true;
  error_ = error;
  if (reader_) final_report_ = reader_->report();
  reader_.reset();  // closes the file
  replay_.next.reset();
  if (!error.empty()) ctx_->requestStop("carmen_player: " + error);
  ctx_->reportProgress(1.0);
  ctx_->finished();
}

void CarmenPlayer::summarize(Summary& out) const {
  const io::ParseReport& r = reader_ ? reader_->report() : final_report_;
  out["records_read"] = static_cast<std::int64_t>(r.records);
  out["lines_skipped"] = static_cast<std::int64_t>(r.skipped);
  std::ostringstream skipped;
  for (const auto& [reason, count] : r.skipped_by_reason)
    skipped << (skipped.tellp() > 0 ? ", " : "") << reason << ": " << count;
  out["skipped"] = skipped.str();
  out["scans_published"] = scans_;
  out["odom_published"] = odom_;
  out["reference_published"] = reference_;
  out["records_ignored"] = ignored_;
  out["time_reversals"] = replay_.reversals;
  out["first_stamp_s"] = first_stamp_ ? nanosToSeconds(*first_stamp_) : 0.0;
  out["last_stamp_s"] = last_stamp_ ? nanosToSeconds(*last_stamp_) : 0.0;
  out["laser"] = laser_;
  out["odometry_source"] = odometry_;
  out["error"] = error_;
}

TESSERA_REGISTER_ACTOR("carmen_player", CarmenPlayer, CarmenPlayerOptions,
                       "replays a CARMEN laser log (FLASER/ROBOTLASER1/RAWLASER/ODOM) as scans, "
                       "odometry and optionally the log's corrected poses");

}  // namespace tessera::players
