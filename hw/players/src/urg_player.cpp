#include <tessera/players/urg_player.hpp>

#include <tessera/messages/views.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/registry.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <numbers>

namespace tessera::players {
namespace {

[[noreturn]] void fail(const std::string& key, const std::string& what) {
  throw ConfigError("urg_player: option '" + key + "': " + what);
}

bool positiveFinite(double v) {
  return v > 0 && std::isfinite(v);
}

}  // namespace

UrgPlayer::UrgPlayer(UrgPlayerOptions options) : options_(std::move(options)) {
  const auto& o = options_;
  if (o.path.empty())
    fail("path", "is required: the URG log to replay, e.g. --set player.path=exp2.dat.gz");
  std::error_code ec;
  if (!std::filesystem::is_regular_file(o.path, ec))
    fail("path", "'" + o.path + "' is not a readable file");
  if (!positiveFinite(o.wheel_radius)) fail("wheel_radius", "must be > 0");
  if (!positiveFinite(o.half_axle)) fail("half_axle", "must be > 0");
  if (!positiveFinite(o.ticks_per_revolution)) fail("ticks_per_revolution", "must be > 0");
  if (!positiveFinite(o.fov_deg) || o.fov_deg > 360) fail("fov_deg", "must be in (0, 360]");
  if (!(o.min_range >= 0) || !(o.max_range > o.min_range) || !std::isfinite(o.max_range))
    fail("max_range", "must be finite and above min_range");
  if (o.laser_mount.size() != 3 || !std::all_of(o.laser_mount.begin(), o.laser_mount.end(),
                                                [](double v) { return std::isfinite(v); }))
    fail("laser_mount", "needs 3 finite values [x, y, theta]");
  if (!(o.start_time >= 0) || !std::isfinite(o.start_time)) fail("start_time", "must be >= 0");
  if (!(o.end_time >= 0) || !std::isfinite(o.end_time)) fail("end_time", "must be >= 0");
  if (o.end_time > 0 && o.end_time < o.start_time) fail("end_time", "is before start_time");
  if (o.max_scans < 0) fail("max_scans", "must be >= 0");
  mount_ = {o.laser_mount[0], o.laser_mount[1], o.laser_mount[2]};
  model_ = {o.wheel_radius, o.half_axle, o.ticks_per_revolution};
  parse_options_.fov_deg = o.fov_deg;
  parse_options_.zero_is_no_return = o.zero_is_no_return;
  parse_options_.skip_malformed = o.skip_malformed;
  if (o.urg04lx_steps && parse_options_.beams != 682)
    fail("urg04lx_steps", "needs the log's 682 beams (steps 44..725)");
}

void UrgPlayer::configure(ActorContext& ctx) {
  ctx_ = &ctx;
  ctx.declareFiniteSource();
  if (options_.publish_scans) scan_pub_ = ctx.advertise<msg::LaserScan>("scan");
  odom_pub_ = ctx.advertise<msg::Odometry>("odom");
  ctx.callAt(ctx.now(), [this] { step(); });
}

bool UrgPlayer::readNext() {
  if (!reader_) reader_ = std::make_unique<datasets::UrgReader>(options_.path, parse_options_);
  datasets::UrgScan scan;
  while (reader_->next(scan)) {
    if (scan.timestamp_us > 9'000'000'000'000'000)
      throw io::DatasetError(options_.path, 0,
                             "scan " + std::to_string(reader_->report().records) +
                                 ": timestamp beyond the int64 ns range");
    const Nanos stamp = scan.timestamp_us * 1000;
    // Dead reckoning over every line, so a later start keeps the odometry frame of the log.
    if (last_ticks_) {
      const double dl =
          static_cast<double>(scan.left_ticks) - static_cast<double>(last_ticks_->left_ticks);
      const double dr =
          static_cast<double>(scan.right_ticks) - static_cast<double>(last_ticks_->right_ticks);
      last_increment_ = datasets::wheelIncrement(dl, dr, model_);
      last_dt_ = static_cast<double>(scan.timestamp_us - last_ticks_->timestamp_us) * 1e-6;
      pose_ = datasets::advancePose(pose_, last_increment_);
      distance_ += std::abs(last_increment_.distance);
    }
    last_ticks_ = datasets::UrgScan{
        scan.timestamp_us, scan.timestamp, scan.left_ticks, scan.right_ticks, 0, 0, {}};
    if (!first_record_) first_record_ = stamp;
    const double since_first = nanosToSeconds(stamp - *first_record_);
    if (options_.end_time > 0 && since_first > options_.end_time) return false;
    if (options_.start_time > 0 && since_first < options_.start_time) continue;
    replay_.next = Pending{std::move(scan), stamp};
    return true;
  }
  return false;
}

void UrgPlayer::step() {
  if (done_) return;
  try {
    const auto next_step = replay_.advance(
        ctx_->now(), [this] { return readNext(); }, [this](const Pending& p) { publish(p); },
        [this] { return options_.max_scans > 0 && odom_ >= options_.max_scans; });
    if (!next_step) return finish("");
    ctx_->reportProgress(reader_->progress());
    ctx_->callAt(*next_step, [this] { step(); });
  } catch (const std::exception& e) {
    finish(e.what());
  }
}

// The pose published with a scan is the one integrated up to that scan's line (readNext ran
// the integration when it read the line), so publish() must run before the next readNext().
void UrgPlayer::publish(const Pending& p) {
  const Nanos stamp = replay_.timeline.stamp(p.stamp, options_.relative_stamps);
  if (!first_stamp_) first_stamp_ = stamp;
  last_stamp_ = stamp;
  {
    auto loan = odom_pub_.loan();
    auto b = loan.builder();
    setHeader(b.initHeader(), stamp, "odom", odom_pub_.nextSeq());
    b.setChildFrameId("base_link");
    writePose(b.initPose(), tessera::Pose2{pose_.x, pose_.y, pose_.theta});
    auto t = b.initTwist();
    if (last_dt_ > 0) {
      t.setVx(last_increment_.distance / last_dt_);
      t.setOmega(last_increment_.rotation / last_dt_);
    }
    odom_pub_.publish(std::move(loan));
    ++odom_;
  }
  if (!options_.publish_scans) return;
  const auto& s = p.scan;
  auto loan = scan_pub_.loan(s.ranges.size() * sizeof(float) + 256);
  auto b = loan.builder();
  setHeader(b.initHeader(), stamp, "laser", scan_pub_.nextSeq());
  if (options_.urg04lx_steps) {
    // Step k looks at (k - 384) 2 pi / 1024, the first beam being step 44 (as SCIP's PP says).
    constexpr double kStep = 2 * std::numbers::pi / 1024;
    b.setAngleMin(static_cast<float>((44 - 384) * kStep));
    b.setAngleIncrement(static_cast<float>(kStep));
  } else {
    b.setAngleMin(s.angle_min);
    b.setAngleIncrement(s.angle_increment);
  }
  b.setRangeMin(static_cast<float>(options_.min_range));
  b.setRangeMax(static_cast<float>(options_.max_range));
  b.setScanTimeS(0.1f);  // URG-04LX: 10 Hz sweep
  b.setMountX(static_cast<float>(mount_.x));
  b.setMountY(static_cast<float>(mount_.y));
  b.setMountTheta(static_cast<float>(mount_.theta));
  auto ranges = mutableView<float>(b.initRanges(static_cast<unsigned>(s.ranges.size())));
  std::copy(s.ranges.begin(), s.ranges.end(), ranges.begin());
  scan_pub_.publish(std::move(loan));
  ++scans_;
}

void UrgPlayer::finish(const std::string& error) {
  if (done_) return;
  done_ = true;
  error_ = error;
  if (reader_) final_report_ = reader_->report();
  reader_.reset();
  replay_.next.reset();
  if (!error.empty()) ctx_->requestStop("urg_player: " + error);
  ctx_->reportProgress(1.0);
  ctx_->finished();
}

void UrgPlayer::summarize(Summary& out) const {
  const io::ParseReport& r = reader_ ? reader_->report() : final_report_;
  out["records_read"] = static_cast<std::int64_t>(r.records);
  out["lines_skipped"] = static_cast<std::int64_t>(r.skipped);
  out["scans_published"] = scans_;
  out["odom_published"] = odom_;
  out["distance_m"] = distance_;
  out["time_reversals"] = replay_.reversals;
  out["first_stamp_s"] = first_stamp_ ? nanosToSeconds(*first_stamp_) : 0.0;
  out["last_stamp_s"] = last_stamp_ ? nanosToSeconds(*last_stamp_) : 0.0;
  out["error"] = error_;
}

TESSERA_REGISTER_ACTOR("urg_player", UrgPlayer, UrgPlayerOptions,
                       "replays a MinesParisTech/BreezySLAM URG-04LX log as scans and wheel "
                       "odometry");

}  // namespace tessera::players
