// rgbd_loop_detector actor: keyframe messages -> LoopDetector -> KeyframeConstraint messages.
#include <tessera/visual_slam/loop_detector_actor.hpp>

#include <tessera/messages/geometry.hpp>
#include <tessera/messages/keyframe_poses.hpp>
#include <tessera/messages/types.hpp>
#include <tessera/runtime/registry.hpp>
#include <tessera/visual_slam/keyframe_message.hpp>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <limits>
#include <stdexcept>

namespace tessera::visual_slam {
namespace {

std::shared_ptr<const Vocabulary> loadVocabulary(const std::string& path) {
  if (path.empty()) return nullptr;
  try {
    return std::make_shared<const Vocabulary>(Vocabulary::load(path));
  } catch (const std::exception& e) {
    throw ConfigError(std::string("rgbd_loop_detector: vocabulary.path: ") + e.what());
  }
}

// The detector's view of a keyframe message, or the reason it cannot be used.
std::string toLoopKeyframe(msg::Keyframe::Reader m, LoopKeyframe& k) {
  if (std::string why = keyframeMessageError(m); !why.empty()) return why;
  if (std::string(m.getDescriptorType().cStr()) != "u8" ||
      m.getDescriptorBytes() != static_cast<unsigned>(kDescriptorBytes))
    return "keyframe " + std::to_string(m.getId()) +
           ": loop detection needs 32-byte binary (ORB) descriptors";
  const auto in = m.getIntrinsics();
  k.id = m.getId();
  k.camera = {in.getFx(),
              in.getFy(),
              in.getCx(),
              in.getCy(),
              static_cast<int>(in.getWidth()),
              static_cast<int>(in.getHeight())};
  const auto kps = m.getKeypoints();
  const auto pts = m.getPoints();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (unsigned i = 0; i < kps.size(); ++i) {
    k.view.pixels.emplace_back(kps[i].getU(), kps[i].getV());
    k.view.points.push_back(pts[i].getValid()
                                ? Eigen::Vector3d(pts[i].getX(), pts[i].getY(), pts[i].getZ())
                                : Eigen::Vector3d(nan, nan, nan));
  }
  const auto bytes = m.getDescriptors();
  k.view.descriptors = cv::Mat(static_cast<int>(kps.size()), kDescriptorBytes, CV_8UC1);
  std::memcpy(k.view.descriptors.data, bytes.begin(), bytes.size());
  return "";
}

// The kind of a rejection message, for the summary's counters ("keyframe 3: no keypoints" ->
// "no_keypoints"; the id and numbers dropped).
std::string reasonKey(const std::string& why) {
  const auto colon = why.find(": ");
  std::string text = colon == std::string::npos ? why : why.substr(colon + 2);
  std::string key;
  for (char c : text) {
    if (std::isalpha(static_cast<unsigned char>(c)))
      key += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    else if (!key.empty() && key.back() != '_')
      key += '_';
  }
  while (!key.empty() && key.back() == '_') key.pop_back();
  return key.substr(0, 40);
}

}  // namespace

LoopDetectorActor::LoopDetectorActor(LoopDetectorActorOptions options)
    : options_(std::move(options)) {
  try {
    options_.detector.validate();
  } catch (const std::invalid_argument& e) {
    throw ConfigError(std::string("rgbd_loop_detector: detector: ") + e.what());
  }
  auto vocabulary = loadVocabulary(options_.vocabulary.path);
  vocabulary_source_ = vocabulary                                  ? "file"
                       : options_.detector.bootstrap_keyframes > 0 ? "bootstrap"
                                                                   : "none";
  detector_ = std::make_unique<LoopDetector>(options_.detector, std::move(vocabulary));
}

void LoopDetectorActor::configure(ActorContext& ctx) {
  ctx.subscribe<msg::Keyframe>("keyframes", MailboxPolicy::reliable(),
                               [this](const Message<msg::Keyframe>& m) { onKeyframe(m); });
  if (options_.forget_trimmed)
    ctx.subscribe<msg::KeyframePoses>("keyframe_poses", MailboxPolicy::keepLatest(1),
                                      [this](const Message<msg::KeyframePoses>& m) { onPoses(m); });
  pub_ = ctx.advertise<msg::KeyframeConstraint>("loop_constraints");
  if (!options_.loops_file.empty() && !ctx.outputDir().empty()) {
    loops_path_ = (std::filesystem::path(ctx.outputDir()) / options_.loops_file).string();
    // Streamed to a temporary file over the run, renamed into place at stop().
    try {
      loops_out_ = std::make_unique<io::AtomicFile>(loops_path_);
    } catch (const io::FileWriteError& e) {
      throw ConfigError(std::string("rgbd_loop_detector: loops_file: ") + e.what());
    }
    loops_out_->stream()
        << "query_id,candidate_id,query_stamp_ns,candidate_stamp_ns,accepted,rejection,"
           "matches,inliers,inlier_ratio,rms_px,depth_agreement,coverage,fit_rms_m,"
           "pose_disagreement_m,pose_disagreement_rad,x,y,z,qx,qy,qz,qw\n";
  }
}

void LoopDetectorActor::stop() {
  if (loops_out_) {
    try {
      loops_out_->commit();
    } catch (const std::exception& e) {
      loops_error_ = e.what();
      std::cerr << "[rgbd_loop_detector] " << loops_error_ << "\n";
    }
    loops_out_.reset();
  }
}

void LoopDetectorActor::writeRow(const LoopQuery& q) {
  if (!loops_out_ || !q.verification || !q.candidate) return;
  const LoopVerification& v = *q.verification;
  const Eigen::Isometry3d& T = v.candidate_from_query;
  const Eigen::Quaterniond r(T.rotation());
  std::ostream& o = loops_out_->stream();
  o << q.query << ',' << *q.candidate << ',' << stamps_[q.query] << ',' << stamps_[*q.candidate]
    << ',' << (v.accepted ? 1 : 0) << ',' << rejectionName(v.rejection) << ',' << v.matches << ','
    << v.inliers << ',' << v.inlier_ratio << ',' << v.rms_px << ',' << v.depth_agreement << ','
    << v.coverage << ',' << v.fit_rms_m << ',' << v.pose_disagreement_m << ','
    << v.pose_disagreement_rad << ',' << T.translation().x() << ',' << T.translation().y() << ','
    << T.translation().z() << ',' << r.x() << ',' << r.y() << ',' << r.z() << ',' << r.w() << '\n';
}

void LoopDetectorActor::onKeyframe(const Message<msg::Keyframe>& m) {
  ++received_;
  LoopKeyframe k;
  std::string why = toLoopKeyframe(*m, k);
  if (why.empty()) {
    // A keyframe refused for its id (out of order) must not overwrite the stamp of the one held.
    const std::int64_t id = k.id;
    const bool fresh = stamps_.emplace(id, m->getHeader().getStampNs()).second;
    for (const auto& q : detector_->add(std::move(k), &why)) {
      writeRow(q);
      if (q.accepted()) publish(q);
    }
    if (!why.empty() && fresh) stamps_.erase(id);
  }
  if (!why.empty()) {
    std::cerr << "[rgbd_loop_detector] " << why << "; skipped\n";
    ++bad_[reasonKey(why)];
  }
}

void LoopDetectorActor::onPoses(const Message<msg::KeyframePoses>& m) {
  const KeptKeyframes kept(*m);
  for (const std::int64_t id : detector_->ids())
    if (kept.leftGraph(static_cast<std::uint64_t>(id)) && detector_->forget(id)) stamps_.erase(id);
}

void LoopDetectorActor::publish(const LoopQuery& q) {
  const LoopVerification& v = *q.verification;
  auto loan = pub_.loan(1024);
  setHeader(loan->initHeader(), stamps_[q.query], "world", pub_.nextSeq());
  loan->setFromId(static_cast<std::uint32_t>(*q.candidate));
  loan->setToId(static_cast<std::uint32_t>(q.query));
  auto rel = loan->initRelative();
  const Eigen::Isometry3d& T = v.candidate_from_query;
  writePose(rel, Pose3{T.translation(), Eigen::Quaterniond(T.rotation()).normalized()});
  auto cov = rel.initCovariance(36);
  for (unsigned i = 0; i < 36; ++i) cov.set(i, v.covariance(i / 6, i % 6));
  loan->setInliers(static_cast<std::uint32_t>(v.inliers));
  pub_.publish(std::move(loan));
  ++published_;
}

void LoopDetectorActor::summarize(Summary& out) const {
  const auto i64 = [](std::uint64_t x) { return static_cast<std::int64_t>(x); };
  const LoopDetectorStats& s = detector_->stats();
  std::uint64_t bad = 0;
  for (const auto& [reason, n] : bad_) {
    out["bad_" + reason] = i64(n);
    bad += n;
  }
  out["keyframes_received"] = i64(received_);
  out["keyframes_bad"] = i64(bad);
  out["queries"] = i64(s.queries);
  out["candidates"] = i64(s.candidates);
  out["verified"] = i64(s.verified);
  out["rejected"] = i64(s.rejected);
  for (const auto& [reason, n] : s.rejected_by) out["rejected_" + reason] = i64(n);
  for (const auto& [status, n] : s.skipped) out["skipped_" + status] = i64(n);
  out["published"] = i64(published_);
  if (options_.forget_trimmed) {
    out["keyframes_forgotten"] = i64(s.forgotten);
    out["keyframes_held"] = i64(detector_->held());
  }
  out["vocabulary"] = vocabulary_source_;
  if (const Vocabulary* voc = detector_->vocabulary())
    out["vocabulary_words"] = i64(voc->wordCount());
  if (s.bootstrapped) out["bootstrap_s"] = s.bootstrap_seconds;
  if (!loops_path_.empty()) out["loops_file"] = loops_path_;
  if (!loops_error_.empty()) out["loops_file_error"] = loops_error_;
}

TESSERA_REGISTER_ACTOR("rgbd_loop_detector", LoopDetectorActor, LoopDetectorActorOptions,
                       "bag-of-words loop closure over RGB-D keyframes: candidates, geometric "
                       "verification, loop constraints");

}  // namespace tessera::visual_slam
