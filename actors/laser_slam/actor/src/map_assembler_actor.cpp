#include <tessera/laser_slam/map_assembler_actor.hpp>

#include <tessera/messages/views.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/runtime/periodic.hpp>
#include <tessera/runtime/registry.hpp>

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <limits>
#include <optional>
#include <stdexcept>
#include <utility>

namespace tessera::laser_slam {
namespace {

MapAssembler checkedAssembler(const MapAssemblerOptions& o) {
  if (!(std::isfinite(o.publish_period_s) && o.publish_period_s >= 0))
    throw ConfigError("map_assembler: publish_period_s must be >= 0");
  if (o.frame_id.empty()) throw ConfigError("map_assembler: frame_id must not be empty");
  try {
    return MapAssembler(o.resolution);
  } catch (const std::invalid_argument& e) {
    throw ConfigError(e.what());
  }
}

}  // namespace

MapAssemblerActor::MapAssemblerActor(MapAssemblerOptions options)
    : options_(std::move(options)), assembler_(checkedAssembler(options_)) {
  if (!options_.load_state.empty()) loadState();
}

void MapAssemblerActor::loadState() {
  SlamState state;
  try {
    state = loadSlamState(options_.load_state);
  } catch (const SlamStateError& e) {
    throw ConfigError("map_assembler: load_state: " + std::string(e.what()));
  }
  if (state.submaps.empty())
    throw ConfigError("map_assembler: load_state: " + options_.load_state +
                      " holds no submaps, so no map to publish");
  if (state.frame_id != options_.frame_id)
    throw ConfigError("map_assembler: load_state: " + options_.load_state + " is in frame '" +
                      state.frame_id + "', but frame_id is '" + options_.frame_id + "'");
  for (SavedSubmap& s : state.submaps) {
    // The saved origins are the optimised poses: they win over chaining, as the optimiser's do.
    message_pose_[s.id] = s.origin;
    optimized_[s.id] = s.origin;
    finished_[s.id] = s.finished;
    assembler_.setSubmap(s.id, std::move(s.grid));
  }
  for (const SavedConstraint& c : state.constraints) {
    kept_keys_.emplace(c.from, c.to, c.relative.x, c.relative.y, c.relative.theta);
    kept_.push_back(c);
  }
  for (const SavedCamera& c : state.cameras) cameras_[c.camera] = c;
  placeChained();
  noteGridBytes();
  loaded_ = true;
}

std::size_t MapAssemblerActor::gridBytes() const {
  return assembler_.bytes();
}

void MapAssemblerActor::configure(ActorContext& ctx) {
  output_dir_ = ctx.outputDir();
  map_pub_ = ctx.advertise<msg::OccupancyGrid>("map");
  if (loaded_) return;  // serves the saved map: nothing to subscribe to
  ctx.subscribe<msg::Submap>("submaps", MailboxPolicy::reliable(),
                             [this](const Message<msg::Submap>& m) { onSubmap(m); });
  ctx.subscribe<msg::SubmapConstraint>(
      "constraints", MailboxPolicy::reliable(),
      [this](const Message<msg::SubmapConstraint>& m) { onConstraint(m); });
  // Optional: most profiles have no cameras, and nothing need publish calibrations.
  ctx.subscribe<msg::CameraCalibration>(
      "camera_calibrations", MailboxPolicy::reliable().asOptional(),
      [this](const Message<msg::CameraCalibration>& m) { onCameraCalibration(m); });
  if (options_.optimized_poses)
    ctx.subscribe<msg::SubmapPoses>(
        "submap_poses", MailboxPolicy::keepLatest(1),
        [this](const Message<msg::SubmapPoses>& m) { onOptimizedPoses(m); });
  addPeriodicTimer(ctx, options_.publish_period_s, [this] {
    if (dirty_) publishMap();
  });
}

void MapAssemblerActor::onSubmap(const Message<msg::Submap>& m) {
  const int id = static_cast<int>(m->getId());
  if (trimmed_.count(id)) {
    ++ignored_trimmed_;
    return;
  }
  const auto g = m->getGrid();
  tessera::grid::OccupancyMap grid;
  grid.resolution = g.getResolution();
  grid.width = static_cast<int>(g.getWidth());
  grid.height = static_cast<int>(g.getHeight());
  grid.origin = toPose2(g.getOrigin());
  const auto cells = viewInt8(g.getCells());
  grid.cells.assign(cells.begin(), cells.end());
  const tessera::Pose2 global = toPose2(m->getGlobalPose());
  try {
    if (!global.isFinite())
      throw std::invalid_argument("map_assembler: submap " + std::to_string(id) +
                                  " has a non-finite global pose");
    assembler_.setSubmap(id, std::move(grid));
  } catch (const std::invalid_argument& e) {
    // A malformed submap is reported and left out; the rest of the map is still drawn.
    std::cerr << "[map_assembler] " << e.what() << "\n";
    ++submaps_rejected_;
    return;
  }
  message_pose_[id] = global;
  finished_[id] = m->getFinished();
  last_stamp_ = std::max(last_stamp_, m->getHeader().getStampNs());
  ++submaps_;
  placeChained();
  noteGridBytes();
  dirty_ = true;
}

void MapAssemblerActor::onConstraint(const Message<msg::SubmapConstraint>& m) {
  ++constraints_;
  if (trimmed_.count(static_cast<int>(m->getFromId())) ||
      trimmed_.count(static_cast<int>(m->getToId()))) {
    ++ignored_trimmed_;
    return;
  }
  const tessera::Pose2 relative = toPose2(m->getRelative());
  keepConstraint(m, relative);
  if (m->getKind() != msg::SubmapConstraint::Kind::HAND_OVER) return;
  if (!relative.isFinite()) {
    std::cerr << "[map_assembler] hand-over " << m->getFromId() << " -> " << m->getToId()
              << " has a non-finite pose; ignored\n";
    ++constraints_rejected_;
    return;
  }
  handover_[static_cast<int>(m->getToId())] = {static_cast<int>(m->getFromId()), relative};
  placeChained();
  dirty_ = true;
}

void MapAssemblerActor::keepConstraint(const Message<msg::SubmapConstraint>& m,
                                       const tessera::Pose2& relative) {
  // For the saved state: every distinct constraint as received (the optimiser fuses them; a
  // later run can do the same). One without a usable covariance has no information to save.
  SavedConstraint c;
  c.from = static_cast<int>(m->getFromId());
  c.to = static_cast<int>(m->getToId());
  c.relative = relative;
  c.revisit = m->getKind() == msg::SubmapConstraint::Kind::REVISIT;
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  const bool read = relative.isFinite() && c.from != c.to &&
                    readCovariance(m->getRelative(), cov) && cov.allFinite() &&
                    (cov - cov.transpose()).cwiseAbs().maxCoeff() <=
                        1e-9 * std::max(1.0, cov.cwiseAbs().maxCoeff());
  const Eigen::LLT<Eigen::Matrix3d> llt(cov);  // fails on the zero matrix of an unread one
  if (!read || llt.info() != Eigen::Success) {
    ++constraints_unsaved_;
    return;
  }
  const Eigen::Matrix3d inv = llt.solve(Eigen::Matrix3d::Identity());
  c.information = 0.5 * (inv + inv.transpose());  // exactly symmetric
  if (!c.information.allFinite()) {
    ++constraints_unsaved_;
    return;
  }
  if (!kept_keys_.emplace(c.from, c.to, relative.x, relative.y, relative.theta).second) return;
  kept_.push_back(c);
}

void MapAssemblerActor::onOptimizedPoses(const Message<msg::SubmapPoses>& m) {
  ++pose_updates_;
  // Cumulative: a list as long as the last one names nothing new.
  if (m->hasTrimmed() && m->getTrimmed().size() != trimmed_listed_) {
    trimmed_listed_ = m->getTrimmed().size();
    for (const auto id : m->getTrimmed())
      if (trimmed_.insert(static_cast<int>(id)).second) dropTrimmed(static_cast<int>(id));
  }
  for (const auto p : m->getPoses()) {
    const tessera::Pose2 pose = toPose2(p.getPose());
    if (pose.isFinite()) optimized_[static_cast<int>(p.getId())] = pose;
  }
  last_stamp_ = std::max(last_stamp_, m->getHeader().getStampNs());
  placeChained();
  dirty_ = true;
}

void MapAssemblerActor::dropTrimmed(int id) {
  assembler_.removeSubmap(id);
  message_pose_.erase(id);
  handover_.erase(id);
  optimized_.erase(id);
  finished_.erase(id);
  std::erase_if(kept_, [id](const SavedConstraint& c) { return c.from == id || c.to == id; });
  std::erase_if(kept_keys_,
                [id](const auto& k) { return std::get<0>(k) == id || std::get<1>(k) == id; });
}

void MapAssemblerActor::onCameraCalibration(const Message<msg::CameraCalibration>& m) {
  ++calibrations_received_;
  SavedCamera c;
  c.camera = m->getCameraId();
  c.submap = static_cast<int>(std::min<std::uint32_t>(
      m->getSubmapId(), static_cast<std::uint32_t>(std::numeric_limits<int>::max())));
  c.stamp_ns = m->getHeader().getStampNs();
  const auto h = m->getHomography();
  for (unsigned k = 0; k < std::min(h.size(), 9u); ++k) c.floor_to_pixel(k / 3, k % 3) = h[k];
  c.rms_px = m->getRmsPx();
  c.coverage = m->getCoverage();
  c.condition = m->getCondition();
  const auto count = [](std::uint32_t v) {
    return static_cast<int>(std::min<std::uint32_t>(v, std::numeric_limits<int>::max()));
  };
  c.pairs = count(m->getPairs());
  c.inliers = count(m->getInliers());
  std::string problem = h.size() == 9
                            ? floorCameraCalibrationProblem(c)
                            : "homography: must hold 9 values, got " + std::to_string(h.size());
  if (!problem.empty()) {
    // Saving it would fail the whole state: reported and left out (an older one is kept).
    std::cerr << "[map_assembler] camera " << c.camera << " calibration in submap " << c.submap
              << " ignored: " << problem << "\n";
    ++calibrations_rejected_;
    return;
  }
  cameras_[c.camera] = c;  // a re-calibration replaces the older one
}

void MapAssemblerActor::placeChained() {
  // Submap poses follow the chain of hand-overs from the first submap; a submap whose chain is
  // broken falls back to the pose its own message carries.
  std::map<int, tessera::Pose2> placed;
  for (const auto& [id, msg_pose] : message_pose_) {
    tessera::Pose2 pose = msg_pose;
    const auto h = handover_.find(id);
    if (const auto o = optimized_.find(id); o != optimized_.end()) {
      pose = o->second;
    } else if (h != handover_.end()) {
      const auto from = placed.find(h->second.first);
      if (from != placed.end()) pose = from->second * h->second.second;
    }
    placed[id] = pose;
    assembler_.setPose(id, pose);
  }
}

void MapAssemblerActor::publishMap() {
  const tessera::grid::OccupancyMap map = assembler_.assemble();
  if (map.empty()) return;
  // The cells go in a blob: every one is copied in, so they need no zeroing first.
  auto loan = map_pub_.loanWithBlob(map.cells.size(), 512);
  setHeader(loan->initHeader(), last_stamp_, options_.frame_id, map_pub_.nextSeq());
  loan->setResolution(static_cast<float>(map.resolution));
  loan->setWidth(static_cast<std::uint32_t>(map.width));
  loan->setHeight(static_cast<std::uint32_t>(map.height));
  writePose(loan->initOrigin(), tessera::Pose2{map.origin.x, map.origin.y, map.origin.theta});
  std::memcpy(loan.blob().data(), map.cells.data(), map.cells.size());
  loan->adoptCells(loan.blobData());
  map_pub_.publish(std::move(loan));
  map_width_ = map.width;
  map_height_ = map.height;
  dirty_ = false;
  ++maps_published_;
}

void MapAssemblerActor::start() {
  if (loaded_) publishMap();
}

void MapAssemblerActor::stop() {
  publishMap();
  if (!options_.state_dir.empty() && !output_dir_.empty()) writeState();
}

void MapAssemblerActor::writeState() {
  // Written one submap at a time: only one submap is unpacked at once (the packed cells stay in
  // the assembler), so saving adds one grid to the end-of-run peak, not the whole map.
  // stop() must not throw: a failed write is logged and reported in the summary.
  const std::filesystem::path dir = std::filesystem::path(output_dir_) / options_.state_dir;
  try {
    SlamStateWriter writer(dir, options_.frame_id);  // creates nothing until the first submap
    std::set<int> ids;
    for (const auto& [id, finished] : finished_) {
      if (!assembler_.hasPose(id)) continue;
      std::optional<tessera::grid::OccupancyMap> grid = assembler_.grid(id);  // unpacked
      if (!grid) continue;
      writer.addSubmap({id, assembler_.pose(id), std::move(*grid), finished});
      ids.insert(id);
    }
    if (ids.empty()) return;
    std::size_t constraints = 0;
    for (const SavedConstraint& c : kept_) {
      if (ids.count(c.from) && ids.count(c.to)) {
        writer.addConstraint(c);
        ++constraints;
      } else {
        std::cerr << "[map_assembler] constraint " << c.from << " -> " << c.to
                  << " names a submap that never arrived; not saved\n";
        ++constraints_unsaved_;
      }
    }
    std::size_t cameras = 0;
    for (const auto& [id, c] : cameras_) {
      if (ids.count(c.submap)) {
        writer.addCamera(c);
        ++cameras;
      } else {
        std::cerr << "[map_assembler] camera " << id << " was calibrated in submap " << c.submap
                  << ", which never arrived; not saved\n";
        ++cameras_unsaved_;
      }
    }
    writer.finish();
    state_path_ = dir.string();
    state_submaps_ = ids.size();
    state_constraints_ = constraints;
    state_cameras_ = cameras;
  } catch (const std::exception& e) {
    state_error_ = e.what();
    std::cerr << "[map_assembler] saving the SLAM state failed: " << state_error_ << "\n";
  }
}

void MapAssemblerActor::summarize(Summary& out) const {
  const auto i64 = [](std::uint64_t v) { return static_cast<std::int64_t>(v); };
  out["submaps_received"] = i64(submaps_);
  out["constraints_received"] = i64(constraints_);
  out["maps_published"] = i64(maps_published_);
  out["map_width"] = static_cast<std::int64_t>(map_width_);
  out["map_height"] = static_cast<std::int64_t>(map_height_);
  if (submaps_rejected_ > 0) out["submaps_rejected"] = i64(submaps_rejected_);
  out["memory_mb"] = static_cast<double>(gridBytes()) / (1024.0 * 1024.0);  // MiB, as peak_rss_mb
  out["memory_peak_mb"] = static_cast<double>(grid_bytes_peak_) / (1024.0 * 1024.0);
  if (constraints_rejected_ > 0) out["constraints_rejected"] = i64(constraints_rejected_);
  if (!trimmed_.empty()) {
    out["submaps_trimmed"] = i64(trimmed_.size());
    out["submaps_held"] = i64(assembler_.size());
    out["ignored_trimmed"] = i64(ignored_trimmed_);
  }
  if (options_.optimized_poses) out["optimized_pose_updates"] = i64(pose_updates_);
  if (!loaded_) out["camera_calibrations_received"] = i64(calibrations_received_);
  if (calibrations_rejected_ > 0) out["camera_calibrations_rejected"] = i64(calibrations_rejected_);
  out["cameras"] = static_cast<std::int64_t>(cameras_.size());
  if (loaded_) out["state_loaded"] = options_.load_state;
  if (!state_path_.empty()) {
    out["state_path"] = state_path_;
    out["state_submaps"] = i64(state_submaps_);
    out["state_constraints"] = i64(state_constraints_);
    out["state_cameras"] = i64(state_cameras_);
  }
  if (cameras_unsaved_ > 0) out["state_cameras_unsaved"] = i64(cameras_unsaved_);
  if (constraints_unsaved_ > 0) out["state_constraints_unsaved"] = i64(constraints_unsaved_);
  if (!state_error_.empty()) out["state_write_error"] = state_error_;
}

TESSERA_REGISTER_ACTOR("map_assembler", MapAssemblerActor, MapAssemblerOptions,
                       "draws all submaps into one global occupancy grid at their poses");

}  // namespace tessera::laser_slam
