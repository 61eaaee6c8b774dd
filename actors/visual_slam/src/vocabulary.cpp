// Vocabulary training (hierarchical k-medians over binary descriptors, TBB over clusters), the
// descriptor-to-word lookup, transform() and the L1 score. Files are in vocabulary_io.cpp.
#include <tessera/visual_slam/vocabulary.hpp>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstring>
#include <deque>
#include <limits>
#include <memory>
#include <mutex>
#include <random>

namespace tessera::visual_slam {

BinaryDescriptor toBinaryDescriptor(const std::uint8_t* bytes) {
  BinaryDescriptor d{};
  for (int i = 0; i < kDescriptorBytes; ++i)
    d[static_cast<std::size_t>(i / 8)] |= static_cast<std::uint64_t>(bytes[i]) << (8 * (i % 8));
  return d;
}

int hammingDistance(const BinaryDescriptor& a, const BinaryDescriptor& b) {
  return std::popcount(a[0] ^ b[0]) + std::popcount(a[1] ^ b[1]) + std::popcount(a[2] ^ b[2]) +
         std::popcount(a[3] ^ b[3]);
}

double l1Norm(const BowVector& v) {
  double n = 0;
  for (const auto& [w, x] : v) n += std::abs(x);
  return n;
}

double l1Score(const BowVector& a, const BowVector& b) {
  const double na = l1Norm(a), nb = l1Norm(b);
  if (na <= 0 || nb <= 0) return 0;
  // Words in only one vector add their whole weight to the distance; both vectors sum to 1 after
  // normalising, so 1 - 1/2 sum|a - b| = 1/2 sum over common words of (|a| + |b| - |a - b|).
  double common = 0;
  auto i = a.begin(), j = b.begin();
  while (i != a.end() && j != b.end()) {
    if (i->first < j->first) {
      ++i;
    } else if (j->first < i->first) {
      ++j;
    } else {
      const double x = std::abs(i->second / na), y = std::abs(j->second / nb);
      common += x + y - std::abs(x - y);
      ++i;
      ++j;
    }
  }
  return std::clamp(0.5 * common, 0.0, 1.0);
}

void VocabularyTrainOptions::validate() const {
  if (k < 2) throw std::invalid_argument("vocabulary k must be >= 2");
  if (levels < 1) throw std::invalid_argument("vocabulary L must be >= 1");
  if (max_iterations < 1) throw std::invalid_argument("vocabulary max_iterations must be >= 1");
  // k^L words must fit the 32-bit word ids with room to spare.
  if (std::pow(static_cast<double>(k), levels) > 1e9)
    throw std::invalid_argument("vocabulary k^L must be <= 1e9");
}

namespace {

// A node while training; flattened into Vocabulary::nodes_ (breadth first) at the end.
struct TrainNode {
  BinaryDescriptor centre{};
  std::vector<std::unique_ptr<TrainNode>> children;
};

std::uint64_t mixSeed(std::uint64_t seed, std::uint64_t child) {
  // splitmix64 step: child seeds independent of the order threads reach the nodes.
  std::uint64_t z = seed + 0x9e3779b97f4a7c15ULL * (child + 1);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

// Centre of a cluster under the Hamming distance: each bit set when most members have it.
BinaryDescriptor majority(const std::vector<BinaryDescriptor>& all,
                          const std::vector<std::uint32_t>& members) {
  std::array<std::uint32_t, 256> ones{};
  for (auto m : members) {
    const auto& d = all[m];
    for (int bit = 0; bit < 256; ++bit)
      ones[static_cast<std::size_t>(bit)] +=
          (d[static_cast<std::size_t>(bit / 64)] >> (bit % 64)) & 1U;
  }
  BinaryDescriptor c{};
  for (int bit = 0; bit < 256; ++bit)
    if (2 * ones[static_cast<std::size_t>(bit)] > members.size())
      c[static_cast<std::size_t>(bit / 64)] |= std::uint64_t{1} << (bit % 64);
  return c;
}

class Trainer {
 public:
  Trainer(const std::vector<BinaryDescriptor>& all, const VocabularyTrainOptions& o)
      : all_(all), o_(o) {}

  void build(TrainNode& node, const std::vector<std::uint32_t>& members, int depth,
             std::uint64_t seed) {
    if (depth >= o_.levels || members.size() <= 1) return;
    // Equal descriptors cannot be split: they stay one leaf.
    if (std::all_of(members.begin(), members.end(),
                    [&](std::uint32_t m) { return all_[m] == all_[members.front()]; }))
      return;
    auto clusters = cluster(members, seed);
    node.children.resize(clusters.size());
    for (std::size_t c = 0; c < clusters.size(); ++c) {
      node.children[c] = std::make_unique<TrainNode>();
      node.children[c]->centre = clusters[c].first;
    }
    report(members.size());
    tbb::parallel_for(std::size_t{0}, clusters.size(), [&](std::size_t c) {
      build(*node.children[c], clusters[c].second, depth + 1, mixSeed(seed, c));
    });
  }

 private:
  using Cluster = std::pair<BinaryDescriptor, std::vector<std::uint32_t>>;

  std::vector<Cluster> cluster(const std::vector<std::uint32_t>& members, std::uint64_t seed) {
    const std::size_t n = members.size();
    const auto k = static_cast<std::size_t>(o_.k);
    std::vector<Cluster> out;
    if (n <= k) {  // one leaf per distinct descriptor, as DBoW does (equal ones share a leaf)
      for (auto m : members) {
        auto same = std::find_if(out.begin(), out.end(),
                                 [&](const Cluster& c) { return c.first == all_[m]; });
        if (same == out.end())
          out.push_back({all_[m], {m}});
        else
          same->second.push_back(m);
      }
      return out;
    }
    // k-means++ seeding: each next centre drawn with probability proportional to the squared
    // distance to the nearest centre so far.
    std::mt19937_64 rng(seed);
    std::vector<BinaryDescriptor> centres;
    centres.push_back(all_[members[std::uniform_int_distribution<std::size_t>(0, n - 1)(rng)]]);
    std::vector<double> d2(n, std::numeric_limits<double>::max());
    while (centres.size() < k) {
      double total = 0;
      for (std::size_t i = 0; i < n; ++i) {
        const double d = hammingDistance(all_[members[i]], centres.back());
        d2[i] = std::min(d2[i], d * d);
        total += d2[i];
      }
      if (total <= 0) break;  // every member equals a centre already
      double pick = std::uniform_real_distribution<double>(0, total)(rng);
      std::size_t i = 0;
      for (; i + 1 < n; ++i) {
        pick -= d2[i];
        if (pick < 0) break;
      }
      centres.push_back(all_[members[i]]);
    }
    // k-medians: assign to the nearest centre, move centres to the bitwise majority, until the
    // assignment stops changing.
    std::vector<std::uint32_t> label(n, std::numeric_limits<std::uint32_t>::max());
    for (int it = 0; it < o_.max_iterations; ++it) {
      std::atomic<bool> changed{false};
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 2048), [&](const auto& r) {
        bool any = false;
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
          std::uint32_t best = 0;
          int best_d = std::numeric_limits<int>::max();
          for (std::size_t c = 0; c < centres.size(); ++c) {
            const int d = hammingDistance(all_[members[i]], centres[c]);
            if (d < best_d) {
              best_d = d;
              best = static_cast<std::uint32_t>(c);
            }
          }
          if (label[i] != best) {
            label[i] = best;
            any = true;
          }
        }
        if (any) changed = true;
      });
      // Stop with labels that match the centres (the last step is an assignment), so every
      // member reaches its cluster through lookup()'s nearest-centre descent.
      if (!changed || it + 1 == o_.max_iterations) break;
      std::vector<std::vector<std::uint32_t>> groups(centres.size());
      for (std::size_t i = 0; i < n; ++i) groups[label[i]].push_back(members[i]);
      for (std::size_t c = 0; c < centres.size(); ++c)
        if (!groups[c].empty()) centres[c] = majority(all_, groups[c]);
    }
    std::vector<std::vector<std::uint32_t>> groups(centres.size());
    for (std::size_t i = 0; i < n; ++i) groups[label[i]].push_back(members[i]);
    for (std::size_t c = 0; c < centres.size(); ++c)
      if (!groups[c].empty()) out.push_back({centres[c], std::move(groups[c])});
    return out;
  }

  void report(std::size_t clustered) {
    const auto nodes = ++nodes_done_;
    const auto sum = descriptors_done_ += clustered;
    if (o_.progress && nodes % 500 == 0) {
      const std::lock_guard lock(progress_mutex_);
      o_.progress(nodes, sum);
    }
  }

  const std::vector<BinaryDescriptor>& all_;
  const VocabularyTrainOptions& o_;
  std::atomic<std::size_t> nodes_done_{0};
  std::atomic<std::size_t> descriptors_done_{0};
  std::mutex progress_mutex_;
};

void checkDescriptors(const cv::Mat& m) {
  if (m.empty()) return;
  if (m.type() != CV_8UC1 || m.cols != kDescriptorBytes)
    throw std::invalid_argument("vocabulary: descriptors must be CV_8UC1 with 32 columns (ORB)");
}

}  // namespace

Vocabulary Vocabulary::train(const std::vector<cv::Mat>& images,
                             const VocabularyTrainOptions& options) {
  options.validate();
  std::vector<BinaryDescriptor> all;
  for (const auto& m : images) {
    checkDescriptors(m);
    for (int r = 0; r < m.rows; ++r) all.push_back(toBinaryDescriptor(m.ptr<std::uint8_t>(r)));
  }
  if (all.empty()) throw std::invalid_argument("vocabulary: no descriptors to train on");
  std::vector<std::uint32_t> members(all.size());
  for (std::size_t i = 0; i < all.size(); ++i) members[i] = static_cast<std::uint32_t>(i);

  TrainNode root;
  Trainer(all, options).build(root, members, 0, options.seed);

  // Flatten breadth first: node ids grow with depth, children keep their order.
  Vocabulary v;
  v.k_ = options.k;
  v.levels_ = options.levels;
  v.nodes_.emplace_back();
  std::deque<std::pair<const TrainNode*, NodeId>> queue{{&root, 0}};
  while (!queue.empty()) {
    const auto [t, id] = queue.front();
    queue.pop_front();
    for (const auto& c : t->children) {
      const auto child = static_cast<NodeId>(v.nodes_.size());
      Node n;
      n.parent = id;
      n.descriptor = c->centre;
      n.depth = v.nodes_[id].depth + 1;
      v.nodes_.push_back(n);
      v.nodes_[id].children.push_back(child);
      queue.emplace_back(c.get(), child);
    }
  }
  for (NodeId id = 1; id < v.nodes_.size(); ++id) {
    if (v.nodes_[id].children.empty()) {
      v.nodes_[id].word = static_cast<int>(v.words_.size());
      v.words_.push_back(id);
    }
  }
  if (v.words_.empty()) {  // one distinct descriptor and L >= 1 still gives the root a child
    throw std::invalid_argument("vocabulary: training produced no words");
  }

  // idf = log(N / n_i) from the words the training images' descriptors actually fall in.
  std::vector<std::uint32_t> images_with(v.words_.size(), 0);
  std::vector<std::uint8_t> seen(v.words_.size(), 0);
  for (const auto& m : images) {
    std::fill(seen.begin(), seen.end(), 0);
    for (int r = 0; r < m.rows; ++r)
      seen[v.lookup(toBinaryDescriptor(m.ptr<std::uint8_t>(r)), 0).first] = 1;
    for (std::size_t w = 0; w < seen.size(); ++w) images_with[w] += seen[w];
  }
  const double n_images = static_cast<double>(images.size());
  for (std::size_t w = 0; w < v.words_.size(); ++w) {
    // A word no training image reaches (possible when k-medians stopped before converging) gets
    // 0, as DBoW2 leaves it: it carries no evidence either way.
    v.nodes_[v.words_[w]].weight =
        images_with[w] > 0 ? std::log(n_images / static_cast<double>(images_with[w])) : 0.0;
  }
  return v;
}

std::pair<WordId, NodeId> Vocabulary::lookup(const BinaryDescriptor& d, int direct_depth) const {
  NodeId id = 0;
  NodeId direct = 0;
  while (!nodes_[id].children.empty()) {
    NodeId best = nodes_[id].children.front();
    int best_d = std::numeric_limits<int>::max();
    for (NodeId c : nodes_[id].children) {
      const int dist = hammingDistance(d, nodes_[c].descriptor);
      if (dist < best_d) {
        best_d = dist;
        best = c;
      }
    }
    id = best;
    if (nodes_[id].depth <= direct_depth) direct = id;
  }
  return {static_cast<WordId>(nodes_[id].word), direct};
}

void Vocabulary::transform(const cv::Mat& descriptors, BowVector& bow, FeatureVector& features,
                           int direct_depth) const {
  bow.clear();
  features.clear();
  if (descriptors.empty()) return;
  if (descriptors.type() != CV_8UC1 || descriptors.cols != kDescriptorBytes)
    throw std::invalid_argument(
        "Vocabulary::transform: descriptors must be CV_8UC1 with 32 columns (ORB)");
  if (words_.empty()) throw std::invalid_argument("Vocabulary::transform: empty vocabulary");
  std::vector<std::pair<WordId, double>> hits;
  hits.reserve(static_cast<std::size_t>(descriptors.rows));
  for (int r = 0; r < descriptors.rows; ++r) {
    const auto [word, node] =
        lookup(toBinaryDescriptor(descriptors.ptr<std::uint8_t>(r)), direct_depth);
    features[node].push_back(r);
    const double w = nodes_[words_[word]].weight;
    if (w > 0) hits.emplace_back(word, w);  // a word in every training image says nothing
  }
  std::sort(hits.begin(), hits.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });
  for (const auto& h : hits) {
    if (!bow.empty() && bow.back().first == h.first)
      bow.back().second += h.second;
    else
      bow.push_back(h);
  }
  const double norm = l1Norm(bow);
  if (norm > 0)
    for (auto& e : bow) e.second /= norm;
}

BowVector Vocabulary::transform(const cv::Mat& descriptors) const {
  BowVector bow;
  FeatureVector features;
  transform(descriptors, bow, features, 0);
  return bow;
}

}  // namespace tessera::visual_slam
