// rgbd_loop_detector actor (type name; laser_slam has its own loop_detector): bag-of-words loop
// closure over RGB-D keyframes (LoopDetector, loop_detector.hpp; docs/algorithms.md#loop-closure).
//
// Subscribes:
//   keyframes          msg::Keyframe            reliable: each is transformed with the
//                                               vocabulary, queried against the earlier ones
//                                               (eta, temporal consistency), the accepted
//                                               candidate verified (direct-index matching,
//                                               RANSAC PnP, 3D check), then indexed
//   keyframe_poses     msg::KeyframePoses       keep_latest, only with forget_trimmed (lifelong
//                                               mode): a keyframe the message says left the
//                                               graph (KeptKeyframes, messages/
//                                               keyframe_poses.hpp) is forgotten (LoopDetector::
//                                               forget): never a candidate again, its view
//                                               released. keep_latest: any one message says all,
//                                               and the detector never holds up the graph
// Publishes:
//   loop_constraints   msg::KeyframeConstraint  reliable, each verified loop: from = the earlier
//                                               (candidate) keyframe, to = the query, relative =
//                                               the query's pose in the candidate's frame with
//                                               its covariance, inliers = PnP inliers
// Vocabulary: vocabulary.path names a DBoW2/DBoW3 YAML (.yml, .yml.gz) or our binary file (loaded
// in the constructor; a bad file is a ConfigError). Empty: the detector trains one on the first
// detector.bootstrap_keyframes keyframes (their loops are then searched in order), so a run
// without external data (the simulated office) still closes loops.
// Output (with an output directory): loops_file, a CSV row per verified candidate, accepted or not
// (ids, stamps, the verification's figures, the relative pose), to judge loops against ground
// truth or tune the verifier (docs/algorithms.md#loop-closure).
// A keyframe it cannot use (checks of keyframe_message.hpp, non-binary or non-32-byte
// descriptors, NaN pixels) is counted by reason and skipped, never a crash.
#pragma once

#include <tessera/msg/keyframe.capnp.h>
#include <tessera/io/atomic_file.hpp>
#include <tessera/runtime/actor.hpp>
#include <tessera/runtime/options.hpp>
#include <tessera/visual_slam/loop_detector.hpp>

#include <cstdint>
#include <fstream>
#include <map>
#include <memory>
#include <string>

namespace tessera::visual_slam {

struct VocabularySource {
  std::string path;

  template <class V>
  void visit(V& v) {
    v("path", path,
      "DBoW2/DBoW3 YAML (.yml, .yml.gz) or tessera binary vocabulary; empty: bootstrap from the "
      "first keyframes");
  }
};

struct LoopDetectorActorOptions {
  VocabularySource vocabulary;
  LoopDetectorOptions detector;
  std::string loops_file = "loops.csv";
  bool forget_trimmed = false;

  template <class V>
  void visit(V& v) {
    v("vocabulary", vocabulary, "the bag-of-words vocabulary");
    v("detector", detector, "candidates, verification and the vocabulary bootstrap");
    v("loops_file", loops_file,
      "CSV of every verified candidate in the output directory; empty: none");
    v("forget_trimmed", forget_trimmed,
      "lifelong mode: subscribe to keyframe_poses and forget the keyframes the graph trimmed");
  }
};

class LoopDetectorActor final : public Actor {
 public:
  /// Throws ConfigError on invalid options or an unreadable vocabulary file.
  explicit LoopDetectorActor(LoopDetectorActorOptions options);
  void configure(ActorContext& ctx) override;
  void stop() override;
  /// keyframes_received, keyframes_bad (and bad_<reason>), queries, candidates, verified,
  /// rejected (and rejected_<reason>), skipped_<status>, published, vocabulary source and size.
  void summarize(Summary& out) const override;

  const LoopDetector& detector() const { return *detector_; }

 private:
  void onKeyframe(const Message<msg::Keyframe>& m);
  void onPoses(const Message<msg::KeyframePoses>& m);
  void publish(const LoopQuery& q);
  void writeRow(const LoopQuery& q);

  LoopDetectorActorOptions options_;
  std::unique_ptr<LoopDetector> detector_;
  std::string vocabulary_source_;
  Publisher<msg::KeyframeConstraint> pub_;
  std::map<std::int64_t, std::int64_t> stamps_;  ///< keyframe id -> header stamp [ns]
  std::map<std::string, std::uint64_t> bad_;
  std::uint64_t received_ = 0, published_ = 0;
  std::unique_ptr<io::AtomicFile> loops_out_;  ///< renamed into place at stop()
  std::string loops_path_, loops_error_;
};

}  // namespace tessera::visual_slam
