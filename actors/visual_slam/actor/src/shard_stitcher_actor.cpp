// shard_stitcher actor: shards' front-end recordings -> one keyframe / pose stream.
#include <tessera/visual_slam/shard_stitcher_actor.hpp>

#include <tessera/messages/geometry.hpp>
#include <tessera/messages/message.hpp>
#include <tessera/runtime/recording.hpp>
#include <tessera/runtime/registry.hpp>
#include <tessera/visual_slam/shard_join.hpp>

#include <algorithm>
#include <limits>
#include <map>

namespace tessera::visual_slam {

struct ShardStitcherActor::Output {
  enum class Kind { kKeyframe, kPose, kTruth };
  Nanos stamp = 0;  ///< global
  Kind kind = Kind::kPose;
  std::uint32_t frame = 0;  ///< the frame index of a pose or keyframe (ground truth has none)
  std::size_t shard = 0;
  std::shared_ptr<const MessageStorage> message;
};

namespace {

[[noreturn]] void fail(const std::string& what) {
  throw ConfigError("shard_stitcher: " + what);
}

/// One shard's messages as read, with its shard-local stamps.
struct ShardMessages {
  std::string path;
  std::vector<ShardStitcherActor::Output> messages;
  ShardTrack track;
  Nanos first_stamp = std::numeric_limits<Nanos>::max();
};

ShardMessages readShard(const std::string& path, const ShardStitcherOptions& o, std::size_t k) {
  using Kind = ShardStitcherActor::Output::Kind;
  ShardMessages s;
  s.path = path;
  std::unique_ptr<RecordingReader> reader;
  try {
    RecordingReaderOptions ro;
    ro.topics = {o.keyframes_topic, o.poses_topic, o.ground_truth_topic};
    reader = std::make_unique<RecordingReader>(path, ro);
  } catch (const std::exception& e) {
    fail("recordings[" + std::to_string(k) + "]: " + e.what());
  }
  // Topic index -> kind, each checked against the type this actor reads.
  std::map<std::uint32_t, Kind> kinds;
  const auto& topics = reader->topics();
  const auto expect = [&](const std::string& name, MessageType type, Kind kind) {
    for (std::uint32_t i = 0; i < topics.size(); ++i) {
      if (topics[i].name != name) continue;
      if (topics[i].type_id != type.id)
        fail(path + ": topic '" + name + "' holds " + topics[i].type_name + ", expected " +
             type.name);
      kinds[i] = kind;
    }
  };
  expect(o.keyframes_topic, messageTypeOf<msg::Keyframe>(), Kind::kKeyframe);
  expect(o.poses_topic, messageTypeOf<msg::PoseStamped3D>(), Kind::kPose);
  expect(o.ground_truth_topic, messageTypeOf<msg::GroundTruthPose3D>(), Kind::kTruth);

  RecordedMessage m;
  while (reader->next(m)) {
    const auto kind = kinds.find(m.topic);
    if (kind == kinds.end()) continue;
    ShardStitcherActor::Output out{m.stamp, kind->second, 0, k, m.message};
    try {
      if (kind->second == Kind::kPose) {
        const auto p = readMessage<msg::PoseStamped3D>(m.message);
        s.track.poses.push_back(
            {p->getFrameIndex(), p->getHeader().getStampNs(), toPose3(p->getPose())});
        out.stamp = p->getHeader().getStampNs();
        out.frame = p->getFrameIndex();
      } else if (kind->second == Kind::kKeyframe) {
        const auto kf = readMessage<msg::Keyframe>(m.message);
        out.stamp = kf->getHeader().getStampNs();
        out.frame = kf->getFrameIndex();
      } else {
        out.stamp = readMessage<msg::GroundTruthPose3D>(m.message)->getHeader().getStampNs();
      }
    } catch (const std::exception& e) {
      fail(path + ": a " + topics[m.topic].name + " message: " + e.what());
    }
    s.first_stamp = std::min(s.first_stamp, out.stamp);
    s.messages.push_back(std::move(out));
  }
  if (!reader->losses().empty())
    fail(path + ": damaged (" + reader->losses().front().describe() +
         "); reprocess this shard rather than stitch a gap");
  if (s.track.poses.empty())
    fail(path + ": no " + o.poses_topic + " message: the shard tracked no frame");
  s.track.first_frame =
      std::min_element(s.track.poses.begin(), s.track.poses.end(),
                       [](const auto& a, const auto& b) { return a.frame < b.frame; })
          ->frame;
  return s;
}

}  // namespace

ShardStitcherActor::ShardStitcherActor(ShardStitcherOptions options)
    : options_(std::move(options)) {
  if (options_.recordings.empty())
    fail("option 'recordings': is required: the shards' recordings in frame order");
  std::vector<ShardMessages> shards;
  for (std::size_t k = 0; k < options_.recordings.size(); ++k)
    shards.push_back(readShard(options_.recordings[k], options_, k));
  std::vector<ShardTrack> tracks;
  for (const auto& s : shards) tracks.push_back(s.track);
  std::vector<ShardPlacement> placements;
  try {
    placements = joinShards(tracks);
  } catch (const std::invalid_argument& e) {
    fail(std::string(e.what()) + " (recordings: " + options_.recordings.front() + " ...)");
  }

  // Keep a shard's frames up to the next shard's first tracked frame (by frame index for poses
  // and keyframes, by global stamp for ground truth, which carries no index).
  for (std::size_t k = 0; k < shards.size(); ++k) {
    const ShardPlacement& place = placements[k];
    const bool last = k + 1 == shards.size();
    const std::uint32_t end_frame =
        last ? std::numeric_limits<std::uint32_t>::max() : placements[k + 1].first_frame;
    const Nanos end_stamp = last ? std::numeric_limits<Nanos>::max()
                                 : placements[k + 1].stamp_offset_ns + shards[k + 1].first_stamp;
    if (k > 0) {
      join_frames_.push_back(place.join_frame);
    }
    for (auto& m : shards[k].messages) {
      m.stamp += place.stamp_offset_ns;
      const bool keep = m.kind == Output::Kind::kTruth ? m.stamp < end_stamp : m.frame < end_frame;
      if (keep)
        outputs_.push_back(std::move(m));
      else
        ++stats_.dropped_overlap;
    }
  }
  // Stamp order; at one stamp a frame's pose before its keyframe, as the front end sends them.
  std::stable_sort(outputs_.begin(), outputs_.end(), [](const Output& a, const Output& b) {
    if (a.stamp != b.stamp) return a.stamp < b.stamp;
    return static_cast<int>(a.kind) > static_cast<int>(b.kind);
  });
  placements_ = std::move(placements);
}

ShardStitcherActor::~ShardStitcherActor() = default;

void ShardStitcherActor::configure(ActorContext& ctx) {
  ctx_ = &ctx;
  ctx.declareFiniteSource();
  keyframe_pub_ = ctx.advertise<msg::Keyframe>("keyframes");
  pose_pub_ = ctx.advertise<msg::PoseStamped3D>("camera_pose");
  truth_pub_ = ctx.advertise<msg::GroundTruthPose3D>("ground_truth");
  const Nanos first = outputs_.empty() ? 0 : outputs_.front().stamp;
  ctx.callAt(std::max(ctx.now(), first), [this] { publishDue(); });
}

void ShardStitcherActor::publishDue() {
  const Nanos now = ctx_->now();
  for (; next_ < outputs_.size() && outputs_[next_].stamp <= now; ++next_) {
    const Output& o = outputs_[next_];
    const Pose3& world = placements_[o.shard].world_from_shard;
    if (o.kind == Output::Kind::kKeyframe) {
      const auto in = readMessage<msg::Keyframe>(o.message);
      Loan<msg::Keyframe> loan = keyframe_pub_.loan(o.message->sizeInBytes() + 1024);
      loan.copyFrom(*in);
      loan->getHeader().setStampNs(o.stamp);
      loan->setId(static_cast<std::uint32_t>(stats_.keyframes));
      writePose(loan->getPose(), world * toPose3(in->getPose()));
      keyframe_pub_.publish(std::move(loan));
      ++stats_.keyframes;
    } else if (o.kind == Output::Kind::kPose) {
      const auto in = readMessage<msg::PoseStamped3D>(o.message);
      auto loan = pose_pub_.loan();
      loan.copyFrom(*in);
      loan->getHeader().setStampNs(o.stamp);
      loan->getHeader().setSeq(pose_pub_.nextSeq());
      writePose(loan->getPose(), world * toPose3(in->getPose()));
      pose_pub_.publish(std::move(loan));
      ++stats_.poses;
    } else {
      const auto in = readMessage<msg::GroundTruthPose3D>(o.message);
      auto loan = truth_pub_.loan();
      loan.copyFrom(*in);
      loan->getHeader().setStampNs(o.stamp);
      loan->getHeader().setSeq(truth_pub_.nextSeq());
      truth_pub_.publish(std::move(loan));
      ++stats_.ground_truth;
    }
  }
  if (next_ == outputs_.size()) {
    ctx_->reportProgress(1.0);
    ctx_->finished();
    return;
  }
  ctx_->reportProgress(static_cast<double>(next_) / static_cast<double>(outputs_.size()));
  ctx_->callAt(outputs_[next_].stamp, [this] { publishDue(); });
}

void ShardStitcherActor::summarize(Summary& out) const {
  out["shards"] = static_cast<std::int64_t>(options_.recordings.size());
  out["keyframes"] = stats_.keyframes;
  out["poses"] = stats_.poses;
  out["ground_truth"] = stats_.ground_truth;
  out["dropped_overlap"] = stats_.dropped_overlap;
  std::string joins;
  for (std::size_t i = 0; i < join_frames_.size(); ++i) {
    if (i > 0) joins += ',';
    joins += std::to_string(join_frames_[i]);
  }
  out["join_frames"] = joins;
}

TESSERA_REGISTER_ACTOR("shard_stitcher", ShardStitcherActor, ShardStitcherOptions,
                       "joins the front-end recordings of a batch's shards into one keyframe "
                       "stream (tessera batch)");

}  // namespace tessera::visual_slam
