#include <tessera/mapping/grid_mapper_actor.hpp>

#include <tessera/actor_common/laser_scan.hpp>
#include <tessera/actor_common/pose_source.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/messages/views.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/periodic.hpp>
#include <tessera/runtime/registry.hpp>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace tessera::mapping {
namespace {

GridMapperCoreOptions checkedCore(const GridMapperOptions& o) {
  const auto fail = [](const std::string& what) { throw ConfigError("grid_mapper: " + what); };
  try {
    GridMapper probe(o.grid);  // the core owns the rules for its options
  } catch (const std::invalid_argument& e) {
    fail(std::string("grid.") + e.what());  // the core's message starts with the key
  }
  if (!(std::isfinite(o.publish_period_s) && o.publish_period_s >= 0))
    fail("publish_period_s must be >= 0 (got " + std::to_string(o.publish_period_s) + ")");
  if (!(std::isfinite(o.max_pose_gap_s) && o.max_pose_gap_s > 0))
    fail("max_pose_gap_s must be > 0 (got " + std::to_string(o.max_pose_gap_s) + ")");
  if (o.scan_queue < 1 || o.pose_queue < 1 || o.scan_buffer < 1 || o.pose_history < 2)
    fail("scan_queue, pose_queue, scan_buffer must be >= 1 and pose_history >= 2");
  if (o.frame_id.empty()) fail("frame_id must not be empty");
  if (!(std::isfinite(o.hold_period_s) && o.hold_period_s >= 0))
    fail("hold_period_s must be >= 0 [s] (got " + std::to_string(o.hold_period_s) + ")");
  (void)parsePoseMessage(o.pose_message, "grid_mapper", "pose_message");
  return o.grid;
}

}  // namespace

GridMapperActor::GridMapperActor(GridMapperOptions options)
    : options_(std::move(options)),
      mapper_(checkedCore(options_)),
      poses_(static_cast<std::size_t>(options_.pose_history), options_.max_pose_gap_s) {}

void GridMapperActor::configure(ActorContext& ctx) {
  ctx.subscribe<msg::LaserScan>(
      "scan", MailboxPolicy::keepLatest(static_cast<std::size_t>(options_.scan_queue)),
      [this](const Message<msg::LaserScan>& m) { onScan(m); });
  // Held scans wait for every pose of a trajectory that may come in one burst: none may drop.
  const auto pose_queue = static_cast<std::size_t>(options_.pose_queue);
  subscribePoses(ctx, "pose",
                 options_.hold_scans ? MailboxPolicy::reliable(pose_queue)
                                     : MailboxPolicy::keepLatest(pose_queue),
                 parsePoseMessage(options_.pose_message, "grid_mapper", "pose_message"),
                 [this](Nanos stamp, const tessera::Pose2& pose) { onPose(stamp, pose); });
  map_pub_ = ctx.advertise<msg::OccupancyGrid>("map");
  addPeriodicTimer(ctx, options_.publish_period_s, [this] {
    if (dirty_) publishMap();
  });
}

void GridMapperActor::onScan(const Message<msg::LaserScan>& scan) {
  if (options_.hold_scans) {
    holdScan(scan);
    return;
  }
  // Scans queued behind this one keep their order: only try it now if none is waiting.
  if (waiting_.empty() && tryInsert(scan)) return;
  if (waiting_.size() >= static_cast<std::size_t>(options_.scan_buffer)) {
    waiting_.pop_front();
    ++scans_dropped_buffer_full_;
  }
  waiting_.push_back(scan);
}

void GridMapperActor::holdScan(const Message<msg::LaserScan>& scan) {
  const Nanos stamp = scan->getHeader().getStampNs();
  if (last_held_ && static_cast<double>(stamp - *last_held_) <
                        options_.hold_period_s * static_cast<double>(kNanosPerSecond)) {
    ++scans_not_held_;
    return;
  }
  const tessera::grid::RangeScan ranges = rangeScanOf(*scan);
  const tessera::Pose2 mount = laserMountOf(*scan);
  if (!held_.empty() || !tryInsert(stamp, ranges, mount)) {
    try {
      held_.emplace_back(stamp, ranges, mount);
    } catch (const std::invalid_argument&) {  // range_max NaN, infinite or <= 0: no unit
      ++scans_unusable_;
      return;
    }
    held_bytes_ += held_.back().bytes();
    held_bytes_peak_ = std::max(held_bytes_peak_, held_bytes_);
    held_peak_ = std::max(held_peak_, held_.size());
  }
  last_held_ = stamp;
}

void GridMapperActor::onPose(Nanos stamp, const tessera::Pose2& pose) {
  if (!poses_.add(stamp, pose)) {
    ++poses_invalid_;
    return;
  }
  while (!waiting_.empty() && tryInsert(waiting_.front())) waiting_.pop_front();
  while (!held_.empty()) {
    const PackedRangeScan& h = held_.front();
    if (!tryInsert(h.stampNs(), h.unpack(unpacked_), h.mount())) break;
    held_bytes_ -= h.bytes();
    held_.pop_front();
  }
}

bool GridMapperActor::tryInsert(const Message<msg::LaserScan>& scan) {
  return tryInsert(scan->getHeader().getStampNs(), rangeScanOf(*scan), laserMountOf(*scan));
}

bool GridMapperActor::tryInsert(std::int64_t stamp, const tessera::grid::RangeScan& ranges,
                                const tessera::Pose2& mount) {
  tessera::Pose2 robot;
  switch (poses_.at(stamp, robot)) {
    case tessera::PoseHistory::Lookup::kWait:
      return false;
    case tessera::PoseHistory::Lookup::kTooOld:
    case tessera::PoseHistory::Lookup::kGap:
      ++scans_dropped_no_pose_;
      return true;
    case tessera::PoseHistory::Lookup::kExact:
      ++scans_exact_;
      break;
    case tessera::PoseHistory::Lookup::kInterpolated:
      ++scans_interpolated_;
      break;
  }
  if (mapper_.insert(ranges, robot, mount)) {
    dirty_ = true;
    last_scan_stamp_ = std::max(last_scan_stamp_, stamp);
  }
  return true;
}

void GridMapperActor::publishMap() {
  const tessera::grid::TiledGrid& grid = mapper_.grid();
  const tessera::grid::CellBox box = grid.knownBounds();
  if (box.empty()) return;
  const std::size_t cells = static_cast<std::size_t>(box.width()) * box.height();
  // The cells go in a blob: exportInt8 writes every one, so they need no zeroing first.
  auto loan = map_pub_.loanWithBlob(cells, 512);
  setHeader(loan->initHeader(), last_scan_stamp_, options_.frame_id, map_pub_.nextSeq());
  loan->setResolution(static_cast<float>(grid.resolution()));
  loan->setWidth(static_cast<std::uint32_t>(box.width()));
  loan->setHeight(static_cast<std::uint32_t>(box.height()));
  const Eigen::Vector2d corner = grid.cellCorner(box.min);
  writePose(loan->initOrigin(), tessera::Pose2{corner.x(), corner.y(), 0.0});
  grid.exportInt8(box, {reinterpret_cast<std::int8_t*>(loan.blob().data()), cells});
  loan->adoptCells(loan.blobData());
  map_pub_.publish(std::move(loan));
  dirty_ = false;
  ++maps_published_;
}

void GridMapperActor::stop() {
  // Upstream has stopped: no pose will come for scans still waiting.
  scans_dropped_no_pose_ += waiting_.size() + held_.size();
  waiting_.clear();
  held_.clear();
  held_bytes_ = 0;
  publishMap();  // the final map, even if a timer just sent the same one
}

void GridMapperActor::summarize(Summary& out) const {
  const auto& s = mapper_.stats();
  const auto& grid = mapper_.grid();
  const auto i64 = [](std::uint64_t v) { return static_cast<std::int64_t>(v); };
  out["scans_inserted"] = i64(s.scans_inserted);
  out["scans_skipped"] = i64(s.scans_skipped);
  out["scans_paired_exact"] = i64(scans_exact_);
  out["scans_interpolated"] = i64(scans_interpolated_);
  out["scans_dropped_no_pose"] = i64(scans_dropped_no_pose_ + scans_dropped_buffer_full_);
  out["beams_invalid"] = i64(s.beams_invalid);
  out["map_width"] = static_cast<std::int64_t>(grid.knownBounds().width());
  out["map_height"] = static_cast<std::int64_t>(grid.knownBounds().height());
  out["map_resolution"] = grid.resolution();
  out["known_cells"] = i64(grid.knownCount());
  out["maps_published"] = i64(maps_published_);
  if (s.cells_clipped > 0) out["cells_clipped"] = i64(s.cells_clipped);
  if (poses_invalid_ > 0) out["poses_invalid"] = i64(poses_invalid_);
  if (options_.hold_scans) {
    out["scans_not_held"] = i64(scans_not_held_);  // within hold_period_s of a held one
    out["scans_unusable"] = i64(scans_unusable_);  // no finite, positive range_max to pack by
    out["held_scans_peak"] = static_cast<std::int64_t>(held_peak_);
    out["held_mb_peak"] = static_cast<double>(held_bytes_peak_) / (1024.0 * 1024.0);
  }
}

TESSERA_REGISTER_ACTOR("grid_mapper", GridMapperActor, GridMapperOptions,
                       "occupancy grid mapping with known poses");

}  // namespace tessera::mapping
