// KeyframeDatabase: place recognition over keyframes' BowVectors
// (docs/algorithms.md#bag-of-words-place-recognition), after Galvez-Lopez and Tardos (DBoW2).
//
// Keyframes are added in time order and numbered 0, 1, ... (entries). An inverse index (word ->
// entries holding it, with their weights) finds the earlier entries sharing a word with a query
// without scanning them all. A query v_t is scored against every entry except the most recent
// `recent_excluded` ones (they overlap the current view and would always match):
//   s(v1, v2) = 1 - 1/2 || v1/|v1| - v2/|v2| ||_1               (l1Score)
//   eta(v_t, v_j) = s(v_t, v_j) / s(v_t, v_{t-1})                (normalised by the latest entry)
// The query is skipped when s(v_t, v_{t-1}) < min_normaliser (the camera turned fast or sees
// little: eta would be meaningless); candidates need eta >= alpha. Temporal consistency: a
// candidate counts `consistency` = 1 + that of a candidate of the previous detect() call within
// `consistency_window` entries of it; detect() accepts the best candidate once consistency >=
// `min_consistency`. Geometric verification of the accepted candidate is the caller's step.
//
// remove() forgets an entry (lifelong mode: its keyframe was trimmed): its postings leave the
// inverse index and its vector is released, so it is never a candidate again; the entry keeps its
// number (a few bytes), so the numbering and the consistency window stay as they were.
//
// Not thread-safe: one owner (the loop detector) adds and queries.
#pragma once

#include <tessera/visual_slam/vocabulary.hpp>

#include <cstddef>
#include <optional>
#include <string_view>
#include <vector>

namespace tessera::visual_slam {

struct KeyframeDatabaseOptions {
  int recent_excluded = 20;       ///< most recent entries never returned as candidates
  double min_normaliser = 0.005;  ///< skip the query when s(v_t, v_{t-1}) is below this
  double alpha = 0.3;             ///< smallest normalised score eta of a candidate
  int max_candidates = 10;        ///< ranked candidates kept per query
  int min_common_words = 1;       ///< an entry must share this many words with the query
  int min_consistency = 3;        ///< consecutive consistent queries to accept a loop
  int consistency_window = 3;     ///< [entries] how far a candidate may move between queries

  template <class V>
  void visit(V& v) {
    v("recent_excluded", recent_excluded, "most recent keyframes never loop candidates");
    v("min_normaliser", min_normaliser,
      "skip a query whose score against the previous keyframe is below this");
    v("alpha", alpha, "smallest normalised score of a loop candidate");
    v("max_candidates", max_candidates, "ranked candidates kept per query");
    v("min_common_words", min_common_words, "words a candidate must share with the query");
    v("min_consistency", min_consistency, "consecutive consistent queries to accept a loop");
    v("consistency_window", consistency_window,
      "largest keyframe-index distance between consistent candidates");
  }
  /// Throws std::invalid_argument naming the first bad option.
  void validate() const;
};

struct LoopCandidate {
  std::size_t entry = 0;
  double score = 0;       ///< s(v_t, v_entry)
  double normalised = 0;  ///< eta
  int consistency = 1;    ///< consecutive queries with a candidate near this entry (detect())
};

enum class QueryStatus {
  kTooFewEntries,  ///< nothing older than the excluded recent entries
  kLowNormaliser,  ///< s(v_t, v_{t-1}) < min_normaliser: skipped
  kNoCandidates,   ///< no entry reached alpha
  kNotConsistent,  ///< candidates, none consistent enough yet (detect() only)
  kAccepted,       ///< detect() accepted `accepted`
  kCandidates,     ///< query(): candidates found
};
std::string_view statusName(QueryStatus status);

struct QueryResult {
  QueryStatus status = QueryStatus::kTooFewEntries;
  double normaliser = 0;                  ///< s(v_t, v_{t-1}); 0 without entries
  std::vector<LoopCandidate> candidates;  ///< eta >= alpha, best first (ties: older first)
  std::optional<LoopCandidate> accepted;  ///< detect() only
};

class KeyframeDatabase {
 public:
  explicit KeyframeDatabase(const KeyframeDatabaseOptions& options = {});

  /// Appends an entry (an L1-normalised BowVector, as Vocabulary::transform gives) and returns its
  /// number.
  std::size_t add(BowVector bow);
  /// Candidates for v among the entries, without changing the database or the consistency state.
  QueryResult query(const BowVector& v) const;
  /// query(), then temporal consistency against the previous detect(), then add(v).
  QueryResult detect(const BowVector& v);

  /// Forgets entry `i`; false when it is out of range or already removed.
  bool remove(std::size_t i);

  /// Entries added, removed ones included (the numbering).
  std::size_t size() const { return entries_.size(); }
  /// Entries not removed.
  std::size_t live() const { return entries_.size() - removed_; }
  const BowVector& entry(std::size_t i) const { return entries_.at(i); }
  const KeyframeDatabaseOptions& options() const { return options_; }
  /// Entries holding `word` (ascending).
  std::vector<std::size_t> entriesWith(WordId word) const;

 private:
  struct Posting {
    std::size_t entry;
    double weight;
  };
  KeyframeDatabaseOptions options_;
  std::vector<BowVector> entries_;
  std::vector<double> norms_;                  ///< L1 norm of each entry
  std::vector<std::vector<Posting>> inverse_;  ///< index = word id
  std::vector<LoopCandidate> previous_;        ///< candidates of the previous detect()
  std::vector<char> is_removed_;
  std::size_t removed_ = 0;
};

}  // namespace tessera::visual_slam
