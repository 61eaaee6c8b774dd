// LoopDetector: bag-of-words loop closure over a stream of keyframes
// (docs/algorithms.md#loop-closure): Vocabulary::transform, KeyframeDatabase::detect (eta, temporal
// consistency), then LoopVerifier on the accepted candidate.
//
// Vocabulary: given (loaded from a file by the caller), or, without one, bootstrapped: the first
// `bootstrap_keyframes` keyframes are held back, a vocabulary is trained on their descriptors
// (k-medians, bootstrap_k x bootstrap_levels), and they are then indexed in order as if they had
// just arrived (so a revisit among them is still found). Without a vocabulary and with
// bootstrap_keyframes = 0, nothing is detected. A bootstrapped vocabulary knows only the start of
// the run; it separates places less well than one trained on many images, so verification
// carries the precision.
//
// Keyframes are identified by the caller's ids, which must grow (a keyframe whose id is not above
// the last one taken is refused); a detection names the candidate's id. Keyframes that cannot be
// used (view check fails, no descriptors, id out of order) are counted and skipped. Keeps
// every keyframe's view (descriptors, pixels, points: ~50 kB per keyframe of 1000 features) until
// forget() releases it (lifelong mode: the keyframe graph trimmed it).
// Not thread-safe: one owner.
#pragma once

#include <tessera/visual_slam/camera.hpp>
#include <tessera/visual_slam/keyframe_database.hpp>
#include <tessera/visual_slam/loop_verifier.hpp>
#include <tessera/visual_slam/vocabulary.hpp>

#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace tessera::visual_slam {

struct LoopDetectorOptions {
  KeyframeDatabaseOptions database = defaultDatabase();
  LoopVerifierOptions verifier;
  int bootstrap_keyframes = 30;  ///< keyframes a missing vocabulary is trained on (0 = none)
  int bootstrap_k = 10;          ///< branching factor of the bootstrapped vocabulary
  int bootstrap_levels = 4;      ///< its depth (10^4 words at most: enough for ~30 x 1000)

  static KeyframeDatabaseOptions defaultDatabase() {
    KeyframeDatabaseOptions o;
    // Keyframes are sparse (about one in five frames): a revisit lasts a few keyframes only.
    o.recent_excluded = 10;
    o.min_consistency = 2;
    return o;
  }

  template <class V>
  void visit(V& v) {
    v("database", database, "bag-of-words candidates (eta, temporal consistency)");
    v("verifier", verifier, "geometric verification of a candidate");
    v("bootstrap_keyframes", bootstrap_keyframes,
      "without a vocabulary: train one on this many first keyframes (0 = no loops)");
    v("bootstrap_k", bootstrap_k, "branching factor of the bootstrapped vocabulary");
    v("bootstrap_levels", bootstrap_levels, "depth of the bootstrapped vocabulary");
  }
  /// Throws std::invalid_argument naming the first bad option.
  void validate() const;
};

/// One keyframe as the detector takes it.
struct LoopKeyframe {
  std::int64_t id = 0;
  PinholeCamera camera;  ///< of the pixels
  LoopView view;         ///< features left empty: the detector fills them
};

/// The outcome of one query (a keyframe checked against the earlier ones).
struct LoopQuery {
  std::int64_t query = 0;
  QueryStatus status = QueryStatus::kTooFewEntries;
  std::optional<std::int64_t> candidate;         ///< the database's accepted candidate
  std::optional<LoopVerification> verification;  ///< of that candidate
  bool accepted() const { return verification && verification->accepted; }
};

struct LoopDetectorStats {
  std::size_t keyframes = 0, bad = 0, queries = 0, candidates = 0, verified = 0, rejected = 0;
  std::size_t forgotten = 0;
  std::map<std::string, std::size_t> skipped;      ///< queries without a candidate, by status
  std::map<std::string, std::size_t> rejected_by;  ///< verification failures, by reason
  bool bootstrapped = false;                       ///< the vocabulary was trained here
  double bootstrap_seconds = 0;
};

class LoopDetector {
 public:
  /// `vocabulary` may be null (bootstrap). Throws std::invalid_argument for bad options.
  LoopDetector(const LoopDetectorOptions& options, std::shared_ptr<const Vocabulary> vocabulary);

  /// Adds a keyframe and returns the queries it caused: none while bootstrapping, all held-back
  /// keyframes' when the vocabulary gets trained, else one. `error`, when given, says why a
  /// keyframe was skipped ("" otherwise).
  std::vector<LoopQuery> add(LoopKeyframe keyframe, std::string* error = nullptr);

  /// Releases keyframe `id` (its view and database entry): it is never a candidate again. False
  /// when the detector does not hold it (unknown, skipped, or forgotten before).
  bool forget(std::int64_t id);
  /// The ids of the keyframes held, ascending: what forget() would release.
  std::vector<std::int64_t> ids() const;
  /// Keyframes held (indexed or waiting for the bootstrap), forgotten ones not counted.
  std::size_t held() const { return database_.live() + held_.size(); }

  const LoopDetectorStats& stats() const { return stats_; }
  const Vocabulary* vocabulary() const { return vocabulary_.get(); }
  std::size_t indexed() const { return database_.size(); }
  const LoopDetectorOptions& options() const { return options_; }

 private:
  LoopQuery query(LoopKeyframe keyframe);
  std::vector<LoopQuery> bootstrap();

  LoopDetectorOptions options_;
  std::shared_ptr<const Vocabulary> vocabulary_;
  KeyframeDatabase database_;
  struct Indexed {
    std::size_t entry;  ///< in database_
    LoopKeyframe keyframe;
  };
  /// The keyframes indexed and not forgotten. Ids grow and entries are numbered as they come, so
  /// this is sorted by both, and either finds a keyframe by binary search.
  std::vector<Indexed> live_;
  std::vector<LoopKeyframe> held_;       ///< waiting for the bootstrap, ascending ids
  std::optional<std::int64_t> last_id_;  ///< of the last keyframe taken
  LoopDetectorStats stats_;
};

}  // namespace tessera::visual_slam
