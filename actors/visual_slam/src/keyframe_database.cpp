// KeyframeDatabase: inverse-index scoring, the normalised score with its skip, and temporal
// consistency (see the header).
#include <tessera/visual_slam/keyframe_database.hpp>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace tessera::visual_slam {

void KeyframeDatabaseOptions::validate() const {
  auto need = [](bool ok, const char* what) {
    if (!ok) throw std::invalid_argument(std::string("keyframe database: ") + what);
  };
  need(recent_excluded >= 0, "recent_excluded must be >= 0");
  need(std::isfinite(min_normaliser) && min_normaliser >= 0, "min_normaliser must be >= 0");
  need(std::isfinite(alpha) && alpha >= 0, "alpha must be >= 0");
  need(max_candidates >= 1, "max_candidates must be >= 1");
  need(min_common_words >= 1, "min_common_words must be >= 1");
  need(min_consistency >= 1, "min_consistency must be >= 1");
  need(consistency_window >= 0, "consistency_window must be >= 0");
}

std::string_view statusName(QueryStatus status) {
  switch (status) {
    case QueryStatus::kTooFewEntries:
      return "too_few_entries";
    case QueryStatus::kLowNormaliser:
      return "low_normaliser";
    case QueryStatus::kNoCandidates:
      return "no_candidates";
    case QueryStatus::kNotConsistent:
      return "not_consistent";
    case QueryStatus::kAccepted:
      return "accepted";
    case QueryStatus::kCandidates:
      return "candidates";
  }
  return "?";
}

KeyframeDatabase::KeyframeDatabase(const KeyframeDatabaseOptions& options) : options_(options) {
  options_.validate();
}

std::size_t KeyframeDatabase::add(BowVector bow) {
  const std::size_t id = entries_.size();
  for (const auto& [word, weight] : bow) {
    if (word >= inverse_.size()) inverse_.resize(word + 1);
    inverse_[word].push_back({id, weight});
  }
  norms_.push_back(l1Norm(bow));
  entries_.push_back(std::move(bow));
  is_removed_.push_back(0);
  return id;
}

bool KeyframeDatabase::remove(std::size_t i) {
  if (i >= entries_.size() || is_removed_[i]) return false;
  for (const auto& [word, weight] : entries_[i]) {
    auto& postings = inverse_[word];
    postings.erase(std::remove_if(postings.begin(), postings.end(),
                                  [i](const Posting& p) { return p.entry == i; }),
                   postings.end());
  }
  BowVector().swap(entries_[i]);  // release the memory, not just the size
  norms_[i] = 0;
  is_removed_[i] = 1;
  ++removed_;
  return true;
}

std::vector<std::size_t> KeyframeDatabase::entriesWith(WordId word) const {
  std::vector<std::size_t> out;
  if (word < inverse_.size())
    for (const auto& p : inverse_[word]) out.push_back(p.entry);
  return out;
}

QueryResult KeyframeDatabase::query(const BowVector& v) const {
  QueryResult r;
  if (entries_.empty()) return r;
  r.normaliser = l1Score(v, entries_.back());
  const auto excluded = static_cast<std::size_t>(options_.recent_excluded);
  if (entries_.size() <= excluded) return r;
  const std::size_t limit = entries_.size() - excluded;  // candidates are entries < limit
  if (r.normaliser < options_.min_normaliser || r.normaliser <= 0) {
    r.status = QueryStatus::kLowNormaliser;
    return r;
  }
  // Accumulate 1/2 (|a| + |b| - |a - b|) over the words shared with each entry: the L1 score of
  // normalised vectors (l1Score) without visiting entries that share nothing.
  const double nv = l1Norm(v);
  std::vector<double> score(limit, 0.0);
  std::vector<int> common(limit, 0);
  for (const auto& [word, weight] : v) {
    if (word >= inverse_.size()) continue;
    const double a = std::abs(weight / nv);
    for (const auto& p : inverse_[word]) {
      if (p.entry >= limit) break;  // postings are in entry order
      const double b = std::abs(p.weight / norms_[p.entry]);
      score[p.entry] += 0.5 * (a + b - std::abs(a - b));
      ++common[p.entry];
    }
  }
  for (std::size_t e = 0; e < limit; ++e) {
    if (common[e] < options_.min_common_words) continue;
    const double eta = score[e] / r.normaliser;
    if (eta >= options_.alpha) r.candidates.push_back({e, score[e], eta, 1});
  }
  std::stable_sort(r.candidates.begin(), r.candidates.end(),
                   [](const auto& a, const auto& b) { return a.normalised > b.normalised; });
  if (r.candidates.size() > static_cast<std::size_t>(options_.max_candidates))
    r.candidates.resize(static_cast<std::size_t>(options_.max_candidates));
  r.status = r.candidates.empty() ? QueryStatus::kNoCandidates : QueryStatus::kCandidates;
  return r;
}

QueryResult KeyframeDatabase::detect(const BowVector& v) {
  QueryResult r = query(v);
  for (auto& c : r.candidates) {
    for (const auto& p : previous_) {
      const auto gap = c.entry > p.entry ? c.entry - p.entry : p.entry - c.entry;
      if (gap <= static_cast<std::size_t>(options_.consistency_window))
        c.consistency = std::max(c.consistency, p.consistency + 1);
    }
  }
  // A skipped query (low normaliser) breaks the chain, as any query without candidates does.
  previous_ = r.candidates;
  if (!r.candidates.empty()) {
    r.status = QueryStatus::kNotConsistent;
    for (const auto& c : r.candidates) {  // best first: the first consistent one wins
      if (c.consistency >= options_.min_consistency) {
        r.accepted = c;
        r.status = QueryStatus::kAccepted;
        break;
      }
    }
  }
  add(v);
  return r;
}

}  // namespace tessera::visual_slam
