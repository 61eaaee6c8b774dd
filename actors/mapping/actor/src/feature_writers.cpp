#include <tessera/mapping/feature_writers.hpp>

#include <tessera/line_slam/line_map_io.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/registry.hpp>

#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <stdexcept>

namespace tessera::mapping {
namespace fs = std::filesystem;

namespace {

void requireName(const std::string& value, const char* actor, const char* key) {
  if (value.empty())
    throw ConfigError(std::string(actor) + ": option '" + key + "' must not be empty");
}

// Seconds with exactly 9 decimals, so nanosecond stamps survive a round trip.
std::string seconds(std::int64_t ns) {
  char buf[40];
  const bool neg = ns < 0;
  const std::uint64_t a = neg ? 0 - static_cast<std::uint64_t>(ns) : static_cast<std::uint64_t>(ns);
  std::snprintf(buf, sizeof buf, "%s%" PRIu64 ".%09" PRIu64, neg ? "-" : "", a / 1000000000u,
                a % 1000000000u);
  return buf;
}

/// A CSV streamed over the run: written to a temporary file next to `name`, renamed into place
/// at stop() (finish()), so `name` is only ever a complete file. Throws io::FileWriteError.
std::unique_ptr<tessera::io::AtomicFile> openIn(const std::string& dir, const std::string& name,
                                                const char* header) {
  auto out = std::make_unique<tessera::io::AtomicFile>(fs::path(dir) / name);
  out->stream() << std::setprecision(12) << header << '\n';
  return out;
}

/// stop() must not throw: a failed write is reported (stderr and the summary's error).
void finish(std::unique_ptr<tessera::io::AtomicFile>& out, const ActorContext& ctx,
            std::string& error) {
  if (!out) return;
  try {
    out->commit();
  } catch (const std::exception& e) {
    if (error.empty()) error = e.what();
    std::cerr << ctx.name() << ": " << e.what() << "\n";
  }
  out.reset();
}

}  // namespace

// ---- camera_log_writer ----

CameraLogWriterActor::CameraLogWriterActor(CameraLogWriterOptions options)
    : options_(std::move(options)) {
  requireName(options_.detections_file, "camera_log_writer", "detections_file");
  requireName(options_.events_file, "camera_log_writer", "events_file");
}

void CameraLogWriterActor::configure(ActorContext& ctx) {
  ctx_ = &ctx;
  ctx.subscribe<msg::MarkerDetection>(
      "detections", MailboxPolicy::reliable(), [this](const Message<msg::MarkerDetection>& m) {
        if (!detections_) return;
        detections_->stream() << seconds(m->getHeader().getStampNs()) << ',' << m->getCameraId()
                              << ',' << (m->getDetected() ? 1 : 0) << ',' << m->getU() << ','
                              << m->getV() << ',' << m->getPixelStd() << '\n';
        ++detections_written_;
      });
  ctx.subscribe<msg::CameraEvent>(
      "events", MailboxPolicy::reliable(), [this](const Message<msg::CameraEvent>& m) {
        if (!events_) return;
        events_->stream() << seconds(m->getHeader().getStampNs()) << ',' << m->getCameraId() << ','
                          << (m->getEntered() ? 1 : 0) << '\n';
        ++events_written_;
      });
}

void CameraLogWriterActor::start() {
  if (ctx_->outputDir().empty()) return;
  detections_ = openIn(ctx_->outputDir(), options_.detections_file,
                       "stamp_s,camera_id,detected,u,v,pixel_std");
  events_ = openIn(ctx_->outputDir(), options_.events_file, "stamp_s,camera_id,entered");
}

void CameraLogWriterActor::stop() {
  finish(detections_, *ctx_, error_);
  finish(events_, *ctx_, error_);
}

void CameraLogWriterActor::summarize(Summary& out) const {
  out["detections_written"] = detections_written_;
  out["events_written"] = events_written_;
  if (!error_.empty()) out["error"] = error_;
}

TESSERA_REGISTER_ACTOR("camera_log_writer", CameraLogWriterActor, CameraLogWriterOptions,
                       "streams camera marker detections and enter/leave events to CSV files");

// ---- landmark_log_writer ----

LandmarkLogWriterActor::LandmarkLogWriterActor(LandmarkLogWriterOptions options)
    : options_(std::move(options)) {
  requireName(options_.observations_file, "landmark_log_writer", "observations_file");
  requireName(options_.controls_file, "landmark_log_writer", "controls_file");
}

void LandmarkLogWriterActor::configure(ActorContext& ctx) {
  ctx_ = &ctx;
  ctx.subscribe<msg::LandmarkScan>(
      "landmarks", MailboxPolicy::reliable(), [this](const Message<msg::LandmarkScan>& m) {
        if (!observations_) return;
        const std::string t = seconds(m->getHeader().getStampNs());
        for (const auto o : m->getObservations()) {
          observations_->stream() << t << ',' << o.getId() << ',' << o.getRange() << ','
                                  << o.getBearing() << ',' << o.getRangeStd() << ','
                                  << o.getBearingStd() << '\n';
          ++observations_written_;
        }
      });
  ctx.subscribe<msg::DriveControl>(
      "control", MailboxPolicy::reliable(), [this](const Message<msg::DriveControl>& m) {
        if (!controls_) return;
        controls_->stream() << seconds(m->getHeader().getStampNs()) << ',' << m->getSpeed() << ','
                            << m->getSteering() << ',' << m->getWheelbase() << ',' << m->getDtS()
                            << '\n';
        ++controls_written_;
      });
}

void LandmarkLogWriterActor::start() {
  if (ctx_->outputDir().empty()) return;
  observations_ = openIn(ctx_->outputDir(), options_.observations_file,
                         "stamp_s,id,range,bearing,range_std,bearing_std");
  controls_ =
      openIn(ctx_->outputDir(), options_.controls_file, "stamp_s,speed,steering,wheelbase,dt_s");
}

void LandmarkLogWriterActor::stop() {
  finish(observations_, *ctx_, error_);
  finish(controls_, *ctx_, error_);
}

void LandmarkLogWriterActor::summarize(Summary& out) const {
  out["observations_written"] = observations_written_;
  out["controls_written"] = controls_written_;
  if (!error_.empty()) out["error"] = error_;
}

TESSERA_REGISTER_ACTOR("landmark_log_writer", LandmarkLogWriterActor, LandmarkLogWriterOptions,
                       "streams range-bearing observations and drive controls to CSV files");

// ---- landmark_map_writer ----

LandmarkMapWriterActor::LandmarkMapWriterActor(LandmarkMapWriterOptions options)
    : options_(std::move(options)) {
  requireName(options_.file, "landmark_map_writer", "file");
}

void LandmarkMapWriterActor::configure(ActorContext& ctx) {
  ctx_ = &ctx;
  ctx.subscribe<msg::LandmarkMap>("landmark_map", MailboxPolicy::keepLatest(1),
                                  [this](const Message<msg::LandmarkMap>& m) { latest_ = m; });
}

void LandmarkMapWriterActor::stop() {
  if (ctx_->outputDir().empty()) return;
  if (!latest_) {
    std::cerr << ctx_->name() << ": no landmark map received, nothing written\n";
    return;
  }
  // stop() must not throw: report failures instead.
  try {
    const fs::path path = fs::path(ctx_->outputDir()) / options_.file;
    tessera::io::AtomicFile file(path);  // the old file or the new one, whole
    std::ostream& out = file.stream();
    const auto lms = latest_->getLandmarks();
    out << std::setprecision(12) << "# landmarks in frame '"
        << latest_->getHeader().getFrameId().cStr()
        << "' at t = " << seconds(latest_->getHeader().getStampNs()) << " s: " << lms.size()
        << "\n# id x y\n";
    for (const auto lm : lms) out << lm.getId() << ' ' << lm.getX() << ' ' << lm.getY() << '\n';
    file.commit();
    landmarks_written_ = lms.size();
    path_ = path.string();
  } catch (const std::exception& e) {
    error_ = e.what();
    std::cerr << ctx_->name() << ": " << error_ << "\n";
  }
}

void LandmarkMapWriterActor::summarize(Summary& out) const {
  out["landmarks_path"] = path_;
  out["landmarks_written"] = landmarks_written_;
  if (!error_.empty()) out["error"] = error_;
}

TESSERA_REGISTER_ACTOR("landmark_map_writer", LandmarkMapWriterActor, LandmarkMapWriterOptions,
                       "writes the last landmark map as `id x y` lines");

// ---- line_map_writer ----

LineMapWriterActor::LineMapWriterActor(LineMapWriterOptions options)
    : options_(std::move(options)) {
  if (!(std::isfinite(options_.pixels_per_m) && options_.pixels_per_m > 0))
    throw ConfigError("line_map_writer: option 'pixels_per_m' must be > 0");
}

void LineMapWriterActor::configure(ActorContext& ctx) {
  ctx_ = &ctx;
  ctx.subscribe<msg::LineMap>("line_map", MailboxPolicy::keepLatest(1),
                              [this](const Message<msg::LineMap>& m) { latest_ = m; });
  if (options_.draw_trajectory) {
    ctx.subscribe<msg::PoseStamped>(
        "poses", MailboxPolicy::reliable(), [this](const Message<msg::PoseStamped>& m) {
          const Eigen::Vector2d p(m->getPose().getX(), m->getPose().getY());
          // 2 cm steps are plenty for a drawing and keep long runs small.
          if (p.allFinite() && (trajectory_.empty() || (p - trajectory_.back()).norm() > 0.02))
            trajectory_.push_back(p);
        });
  }
}

void LineMapWriterActor::stop() {
  if (ctx_->outputDir().empty()) return;
  if (!latest_) {
    std::cerr << ctx_->name() << ": no line map received, nothing written\n";
    return;
  }
  // stop() must not throw: report failures instead.
  try {
    std::vector<tessera::line_slam::MapSegment> lines;
    for (const auto f : latest_->getLines()) {
      tessera::line_slam::MapSegment s;
      s.id = f.getId();
      s.r = f.getR();
      s.phi = f.getPhi();
      if (f.getCovariance().size() == 4)
        s.covariance << f.getCovariance()[0], f.getCovariance()[1], f.getCovariance()[2],
            f.getCovariance()[3];
      s.p0 = {f.getX0(), f.getY0()};
      s.p1 = {f.getX1(), f.getY1()};
      s.observations = f.getObservations();
      lines.push_back(s);
    }
    std::vector<tessera::line_slam::MapSegment> walls;
    const fs::path walls_path = fs::path(ctx_->outputDir()) / options_.walls_file;
    if (!options_.walls_file.empty() && fs::exists(walls_path)) {
      walls = tessera::line_slam::readWallSegments(walls_path);
      const auto score = tessera::line_slam::scoreLineMap(lines, walls);
      walls_ = score.walls;
      walls_matched_ = score.walls_matched;
      lines_on_walls_ = score.lines_on_walls;
    }
    if (!options_.lines_file.empty())
      tessera::line_slam::writeLinesCsv(fs::path(ctx_->outputDir()) / options_.lines_file, lines);
    if (!options_.svg_file.empty())
      tessera::line_slam::writeLinesSvg(fs::path(ctx_->outputDir()) / options_.svg_file, lines,
                                        walls, trajectory_, options_.pixels_per_m);
    lines_written_ = static_cast<std::int64_t>(lines.size());
  } catch (const std::exception& e) {
    error_ = e.what();
    std::cerr << ctx_->name() << ": " << error_ << "\n";
  }
}

void LineMapWriterActor::summarize(Summary& out) const {
  out["lines_written"] = lines_written_;
  if (walls_ >= 0) {
    out["walls"] = static_cast<std::int64_t>(walls_);
    out["walls_matched"] = static_cast<std::int64_t>(walls_matched_);
    out["lines_on_walls"] = static_cast<std::int64_t>(lines_on_walls_);
  }
  if (!error_.empty()) out["error"] = error_;
}

TESSERA_REGISTER_ACTOR("line_map_writer", LineMapWriterActor, LineMapWriterOptions,
                       "writes the last line map as CSV and SVG and scores it against true walls");

}  // namespace tessera::mapping
