// keyframe_graph actor: keyframe and loop messages -> KeyframeGraph -> optimised keyframe poses.
#include <tessera/visual_slam/keyframe_graph_actor.hpp>

#include <tessera/mapping/trajectory_io.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/pose_graph/pose_graph_io.hpp>
#include <tessera/runtime/registry.hpp>
#include <tessera/visual_slam/keyframe_message.hpp>

#include <algorithm>
#include <filesystem>
#include <iostream>
#include <limits>
#include <stdexcept>

namespace tessera::visual_slam {
namespace {

KeyframeGraph checkedGraph(const KeyframeGraphOptions& options) {
  try {
    return KeyframeGraph(options);
  } catch (const std::invalid_argument& e) {
    throw ConfigError(std::string("keyframe_graph: graph.") + e.what());
  }
}

}  // namespace

KeyframeGraphActor::KeyframeGraphActor(KeyframeGraphActorOptions options)
    : options_(std::move(options)), graph_(checkedGraph(options_.graph)) {
  if (options_.frame_id.empty()) throw ConfigError("keyframe_graph: frame_id must not be empty");
}

void KeyframeGraphActor::configure(ActorContext& ctx) {
  output_dir_ = ctx.outputDir();
  ctx.subscribe<msg::Keyframe>("keyframes", MailboxPolicy::reliable(),
                               [this](const Message<msg::Keyframe>& m) { onKeyframe(m); });
  if (options_.loops)
    ctx.subscribe<msg::KeyframeConstraint>(
        "loop_constraints", MailboxPolicy::reliable(),
        [this](const Message<msg::KeyframeConstraint>& m) { onConstraint(m); });
  if (!options_.frames_file.empty())
    ctx.subscribe<msg::PoseStamped3D>(
        "camera_pose", MailboxPolicy::reliable(),
        [this](const Message<msg::PoseStamped3D>& m) { onFramePose(m); });
  poses_pub_ = ctx.advertise<msg::KeyframePoses>("keyframe_poses");
}

void KeyframeGraphActor::onFramePose(const Message<msg::PoseStamped3D>& m) {
  const Pose3 p = toPose3(m->getPose());
  if (!p.t.allFinite() || !p.q.coeffs().allFinite()) {
    ++frames_bad_;
    return;
  }
  frames_.emplace_back(m->getHeader().getStampNs(), p);
  baked_.push_back(0);
}

void KeyframeGraphActor::onKeyframe(const Message<msg::Keyframe>& m) {
  ++keyframes_;
  if (const std::string why = keyframeMessageError(*m); !why.empty()) {
    std::cerr << "[keyframe_graph] " << why << "; skipped\n";
    ++keyframes_bad_;
    return;
  }
  const std::int64_t id = m->getId();
  if (!graph_.addKeyframe(id, keyframePose(*m), static_cast<int>(m->getTrackingInliers()))) {
    std::cerr << "[keyframe_graph] " << graph_.lastError() << "; skipped\n";
    ++keyframes_bad_;
    return;
  }
  stamps_[id] = m->getHeader().getStampNs();
  by_stamp_[m->getHeader().getStampNs()] = id;
  tracked_[id] = keyframePose(*m);
  last_stamp_ = std::max(last_stamp_, m->getHeader().getStampNs());
  // A loop that waited for this keyframe may now be in the graph.
  if (graph_.needsOptimization()) optimizeAndPublish();
}

void KeyframeGraphActor::onConstraint(const Message<msg::KeyframeConstraint>& m) {
  ++constraints_;
  last_stamp_ = std::max(last_stamp_, m->getHeader().getStampNs());
  LoopConstraint c;
  c.from = m->getFromId();
  c.to = m->getToId();
  const auto r = m->getRelative();
  c.relative = toPose3(r);
  bool ok = r.getCovariance().size() == 36;
  if (ok)
    for (int i = 0; i < 36; ++i) c.covariance(i / 6, i % 6) = r.getCovariance()[i];
  const double q[] = {r.getQx(), r.getQy(), r.getQz(), r.getQw()};
  ok = ok && (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]) > 1e-12;
  if (!ok) {
    std::cerr << "[keyframe_graph] constraint " << c.from << " -> " << c.to
              << ": covariance needs 36 values and the quaternion a length; skipped\n";
    ++constraints_bad_;
    return;
  }
  if (graph_.addLoop(c) == KeyframeGraph::Outcome::kRejected) {
    std::cerr << "[keyframe_graph] " << graph_.lastError() << "; skipped\n";
    ++constraints_bad_;
    return;
  }
  if (graph_.needsOptimization()) optimizeAndPublish();
}

void KeyframeGraphActor::bakeFrames(std::int64_t id, const Pose3& optimised) {
  if (frames_.empty()) return;
  // The frames that follow keyframe `id`: from its stamp to the next keyframe's.
  const std::int64_t from = stamps_.at(id);
  const auto next = by_stamp_.upper_bound(from);
  const std::int64_t to =
      next == by_stamp_.end() ? std::numeric_limits<std::int64_t>::max() : next->first;
  const Pose3 correction = optimised * tracked_.at(id).inverse();
  const auto by_time = [](const std::pair<std::int64_t, Pose3>& f, std::int64_t t) {
    return f.first < t;
  };
  auto i = static_cast<std::size_t>(
      std::lower_bound(frames_.begin(), frames_.end(), from, by_time) - frames_.begin());
  for (; i < frames_.size() && frames_[i].first < to; ++i) {
    if (baked_[i]) continue;
    frames_[i].second = correction * frames_[i].second;
    baked_[i] = 1;
  }
}

void KeyframeGraphActor::optimizeAndPublish() {
  try {
    const auto s = graph_.optimize();
    ++optimizations_;
    optimize_seconds_ += s.seconds;
    last_chi2_ = s.final_chi2;
    // Lifelong mode: the keyframes newer ones now cover leave the graph, and with them their
    // stamps and tracked poses. Their frames keep the correction they have now (a loop has just
    // tied them to the newer views): it is baked into them, as the best that was known of them.
    if (options_.graph.trimming.enabled) {
      const auto optimised = graph_.poses();
      const std::vector<std::int64_t> gone = graph_.trim();
      for (const std::int64_t id : gone) bakeFrames(id, optimised.at(id));
      for (const std::int64_t id : gone) {
        by_stamp_.erase(stamps_.at(id));
        stamps_.erase(id);
        tracked_.erase(id);
      }
    }
    publishPoses(s.final_chi2, s.iterations);
  } catch (const pose_graph::GraphError& e) {
    // Keep the last poses; the next loop tries again.
    std::cerr << "[keyframe_graph] optimisation failed: " << e.what() << "\n";
    ++solver_failures_;
  }
}

void KeyframeGraphActor::publishPoses(double chi2, int iterations) {
  const auto poses = graph_.poses();
  auto loan = poses_pub_.loan(96 * poses.size() + 256);
  setHeader(loan->initHeader(), last_stamp_, options_.frame_id, poses_pub_.nextSeq());
  auto list = loan->initPoses(static_cast<unsigned>(poses.size()));
  unsigned k = 0;
  for (const auto& [id, p] : poses) {
    list[k].setId(static_cast<std::uint32_t>(id));
    writePose(list[k].initPose(), p);
    ++k;
  }
  loan->setChi2(chi2);
  loan->setIterations(static_cast<std::uint32_t>(std::max(0, iterations)));
  poses_pub_.publish(std::move(loan));
  ++published_;
}

void KeyframeGraphActor::stop() {
  if (graph_.needsOptimization()) optimizeAndPublish();
  if (graph_.keyframes() == 0) return;
  last_chi2_ = graph_.chi2();
  publishPoses(last_chi2_, 0);
  if (!output_dir_.empty()) writeFiles();
}

void KeyframeGraphActor::writeFiles() {
  // stop() must not throw: a failed write is logged and reported in the summary.
  const std::filesystem::path dir(output_dir_);
  try {
    if (!options_.keyframes_file.empty()) {
      mapping::TumWriter writer(dir / options_.keyframes_file);
      for (const auto& [id, p] : graph_.poses()) writer.write({stamps_.at(id), p.t, p.q});
      writer.close();
      keyframes_path_ = (dir / options_.keyframes_file).string();
    }
    if (!options_.g2o_file.empty()) {
      pose_graph::writeG2o(graph_.graph(), dir / options_.g2o_file);
      graph_path_ = (dir / options_.g2o_file).string();
    }
    if (!options_.frames_file.empty()) {
      const auto optimised = graph_.poses();
      std::vector<KeyframeCorrection> corrections;
      for (const auto& [stamp, id] : by_stamp_)
        if (const auto it = optimised.find(id); it != optimised.end())
          corrections.push_back({stamp, tracked_.at(id), it->second});
      const std::vector<Pose3> corrected = correctFramePoses(frames_, std::move(corrections));
      mapping::TumWriter writer(dir / options_.frames_file);
      for (std::size_t i = 0; i < frames_.size(); ++i) {
        const Pose3& p = baked_[i] ? frames_[i].second : corrected[i];
        writer.write({frames_[i].first, p.t, p.q});
      }
      writer.close();
      frames_path_ = (dir / options_.frames_file).string();
    }
  } catch (const std::exception& e) {
    write_error_ = e.what();
    std::cerr << "[keyframe_graph] " << write_error_ << "\n";
  }
}

void KeyframeGraphActor::summarize(Summary& out) const {
  const auto i64 = [](std::uint64_t v) { return static_cast<std::int64_t>(v); };
  out["keyframes_received"] = i64(keyframes_);
  out["keyframes_bad"] = i64(keyframes_bad_);
  out["graph_keyframes"] = i64(graph_.keyframes());
  out["graph_edges"] = i64(graph_.graph().edges.size());
  out["constraints_received"] = i64(constraints_);
  out["constraints_bad"] = i64(constraints_bad_);
  out["loops_added"] = i64(graph_.loops());
  out["constraints_unresolved"] = i64(graph_.pending());
  if (options_.graph.trimming.enabled) out["keyframes_trimmed"] = i64(graph_.trimmed());
  out["optimizations"] = i64(optimizations_);
  out["optimize_s"] = optimize_seconds_;
  out["final_chi2"] = last_chi2_;
  if (solver_failures_ > 0) out["solver_failures"] = i64(solver_failures_);
  if (!keyframes_path_.empty()) out["keyframes_path"] = keyframes_path_;
  if (!graph_path_.empty()) out["graph_path"] = graph_path_;
  if (!options_.frames_file.empty()) {
    out["frames_received"] = i64(frames_.size() + frames_bad_);
    out["frames_bad"] = i64(frames_bad_);
  }
  if (!frames_path_.empty()) out["frames_path"] = frames_path_;
  if (!write_error_.empty()) out["write_error"] = write_error_;
}

TESSERA_REGISTER_ACTOR("keyframe_graph", KeyframeGraphActor, KeyframeGraphActorOptions,
                       "SE(3) pose graph of RGB-D keyframes: odometry and robust loop edges");

}  // namespace tessera::visual_slam
