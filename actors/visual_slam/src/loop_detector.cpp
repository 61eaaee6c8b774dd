// LoopDetector: vocabulary bootstrap, database queries and verification (see the header).
#include <tessera/visual_slam/loop_detector.hpp>

#include <algorithm>
#include <chrono>
#include <stdexcept>
#include <string>
#include <utility>

namespace tessera::visual_slam {

void LoopDetectorOptions::validate() const {
  database.validate();
  verifier.validate();
  if (bootstrap_keyframes < 0)
    throw std::invalid_argument("loop detector: bootstrap_keyframes must be >= 0");
  VocabularyTrainOptions t;
  t.k = bootstrap_k;
  t.levels = bootstrap_levels;
  t.validate();
}

LoopDetector::LoopDetector(const LoopDetectorOptions& options,
                           std::shared_ptr<const Vocabulary> vocabulary)
    : options_((options.validate(), options)),
      vocabulary_(std::move(vocabulary)),
      database_(options.database) {
  if (vocabulary_ && vocabulary_->empty()) vocabulary_.reset();
}

std::vector<LoopQuery> LoopDetector::add(LoopKeyframe keyframe, std::string* error) {
  ++stats_.keyframes;
  std::string why;
  if (last_id_ && keyframe.id <= *last_id_)
    why = "keyframe " + std::to_string(keyframe.id) + ": id out of order; " +
          std::to_string(*last_id_) + " was taken before";
  if (why.empty()) why = keyframe.view.check();
  if (why.empty() && keyframe.view.size() == 0) why = "no features";
  if (why.empty()) {
    try {
      keyframe.camera.validate();
    } catch (const std::invalid_argument& e) {
      why = e.what();
    }
  }
  if (error) *error = why;
  if (!why.empty()) {
    ++stats_.bad;
    return {};
  }
  last_id_ = keyframe.id;
  keyframe.view.features.clear();  // ours to fill, whatever the caller left there
  if (vocabulary_) return {query(std::move(keyframe))};
  if (options_.bootstrap_keyframes == 0) return {};
  held_.push_back(std::move(keyframe));
  if (held_.size() < static_cast<std::size_t>(options_.bootstrap_keyframes)) return {};
  return bootstrap();
}

std::vector<LoopQuery> LoopDetector::bootstrap() {
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<cv::Mat> images;
  for (const auto& k : held_) images.push_back(k.view.descriptors);
  VocabularyTrainOptions t;
  t.k = options_.bootstrap_k;
  t.levels = options_.bootstrap_levels;
  vocabulary_ = std::make_shared<const Vocabulary>(Vocabulary::train(images, t));
  stats_.bootstrapped = true;
  stats_.bootstrap_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::vector<LoopQuery> out;
  std::vector<LoopKeyframe> held = std::move(held_);
  held_.clear();
  for (auto& k : held) out.push_back(query(std::move(k)));
  return out;
}

bool LoopDetector::forget(std::int64_t id) {
  const auto by_id = [](const LoopKeyframe& k, std::int64_t v) { return k.id < v; };
  if (const auto h = std::lower_bound(held_.begin(), held_.end(), id, by_id);
      h != held_.end() && h->id == id) {
    held_.erase(h);
    ++stats_.forgotten;
    return true;
  }
  const auto e = std::lower_bound(live_.begin(), live_.end(), id,
                                  [](const Indexed& k, auto v) { return k.keyframe.id < v; });
  if (e == live_.end() || e->keyframe.id != id) return false;
  database_.remove(e->entry);
  live_.erase(e);
  ++stats_.forgotten;
  return true;
}

std::vector<std::int64_t> LoopDetector::ids() const {
  std::vector<std::int64_t> out;
  out.reserve(held_.size() + live_.size());
  for (const auto& k : held_) out.push_back(k.id);
  for (const auto& k : live_) out.push_back(k.keyframe.id);
  return out;
}

LoopQuery LoopDetector::query(LoopKeyframe keyframe) {
  LoopQuery q;
  q.query = keyframe.id;
  BowVector bow;
  vocabulary_->transform(keyframe.view.descriptors, bow, keyframe.view.features,
                         options_.verifier.direct_depth);
  const QueryResult r = database_.detect(bow);
  ++stats_.queries;
  q.status = r.status;
  if (r.status == QueryStatus::kAccepted && r.accepted) {
    ++stats_.candidates;
    // Never a forgotten entry: the database no longer holds its words.
    const auto c = std::lower_bound(live_.begin(), live_.end(), r.accepted->entry,
                                    [](const Indexed& k, std::size_t v) { return k.entry < v; });
    if (c == live_.end() || c->entry != r.accepted->entry)
      throw std::logic_error("loop detector: database entry " + std::to_string(r.accepted->entry) +
                             " has no keyframe");
    const LoopKeyframe& candidate = c->keyframe;
    q.candidate = candidate.id;
    const LoopVerifier verifier(options_.verifier, keyframe.camera);
    q.verification = verifier.verify(keyframe.view, candidate.view);
    if (q.verification->accepted) {
      ++stats_.verified;
    } else {
      ++stats_.rejected;
      ++stats_.rejected_by[std::string(rejectionName(q.verification->rejection))];
    }
  } else {
    ++stats_.skipped[std::string(statusName(r.status))];
  }
  const std::size_t entry = database_.size() - 1;  // detect() added it
  live_.push_back({entry, std::move(keyframe)});
  return q;
}

}  // namespace tessera::visual_slam
