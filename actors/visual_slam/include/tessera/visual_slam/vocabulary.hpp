// Vocabulary: a bag-of-binary-words vocabulary tree over 256-bit ORB descriptors
// (docs/algorithms.md#bag-of-words-place-recognition), after Galvez-Lopez and Tardos (DBoW2).
//
// The tree has branching factor k and depth L. Every node but the root holds a cluster centre (a
// descriptor); the leaves are the words. Training clusters the descriptors of a set of images by
// hierarchical k-medians (k-means++ seeding from a fixed seed, centres by per-bit majority, the
// mean of binary descriptors under the Hamming distance), recursively, up to depth L; a cluster of
// at most k descriptors gives one leaf per descriptor. Each word's weight is its inverse document
// frequency idf = log(N / n_i): N training images, n_i of them containing the word.
//
// transform() walks each descriptor from the root to the leaf of the nearest centre at every
// level (Hamming distance, first centre on ties) and returns the image's BowVector (word -> sum of
// the word's idf over its features, i.e. tf * idf up to a per-image factor, then L1-normalised) and
// its FeatureVector (direct index: feature indices grouped by their node at a chosen depth).
//
// Files: load() reads DBoW2/DBoW3 text vocabularies (OpenCV FileStorage YAML, also gzip'd .yml.gz)
// and our own binary format (save()); errors name the file and the field. A Vocabulary is
// immutable after construction and safe to share between threads.
#pragma once

#include <opencv2/core.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace tessera::visual_slam {

using WordId = std::uint32_t;
using NodeId = std::uint32_t;
/// A 256-bit ORB descriptor as four 64-bit words (byte i of the descriptor is byte i % 8 of
/// bits[i / 8], little-endian), so the Hamming distance is four popcounts.
using BinaryDescriptor = std::array<std::uint64_t, 4>;
constexpr int kDescriptorBytes = 32;

BinaryDescriptor toBinaryDescriptor(const std::uint8_t* bytes);
int hammingDistance(const BinaryDescriptor& a, const BinaryDescriptor& b);

/// word -> weight, sorted by word, each word once. transform() returns it L1-normalised.
using BowVector = std::vector<std::pair<WordId, double>>;
/// node (at the direct-index depth) -> indices of the features under it (ascending).
using FeatureVector = std::map<NodeId, std::vector<int>>;

/// Sum of |weights|.
double l1Norm(const BowVector& v);
/// s(v1, v2) = 1 - 1/2 || v1/|v1| - v2/|v2| ||_1 in [0, 1] (1 = same distribution, 0 = no word in
/// common or an empty vector).
double l1Score(const BowVector& a, const BowVector& b);

/// A vocabulary file that cannot be used: the message starts with the file and names the field.
class VocabularyError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct VocabularyTrainOptions {
  int k = 10;                 ///< branching factor
  int levels = 5;             ///< depth L of the tree (leaves at depth <= L)
  int max_iterations = 10;    ///< k-medians iterations per node (stops earlier when stable)
  std::uint64_t seed = 5489;  ///< k-means++ seeding; results do not depend on the thread count
  /// Called now and then from the training threads with (nodes built, descriptors clustered so
  /// far summed over nodes); may be empty.
  std::function<void(std::size_t, std::size_t)> progress;
  /// Throws std::invalid_argument naming the first bad option.
  void validate() const;
};

class Vocabulary {
 public:
  struct Node {
    NodeId parent = 0;
    std::vector<NodeId> children;
    BinaryDescriptor descriptor{};
    double weight = 0;  ///< idf for words, 0 for inner nodes
    int word = -1;      ///< word id for leaves, -1 for inner nodes
    int depth = 0;      ///< 0 for the root
  };

  Vocabulary() = default;

  /// Trains on the descriptors of a set of images: one CV_8UC1 matrix of 32-byte rows per image
  /// (images without descriptors count in N). Throws std::invalid_argument for other types or when
  /// there is no descriptor at all.
  static Vocabulary train(const std::vector<cv::Mat>& images,
                          const VocabularyTrainOptions& options = {});

  /// One node as files list it.
  struct NodeRecord {
    NodeId id = 0;  ///< 1..n; 0 is the root, which files do not list
    NodeId parent = 0;
    double weight = 0;
    BinaryDescriptor descriptor{};
  };
  /// Builds from nodes in file order (children keep that order, which breaks distance ties) and
  /// (word id, node id) pairs naming the leaves. Checks ids, parents, depths, that the words are
  /// exactly the leaves; throws VocabularyError whose message starts with `source`.
  static Vocabulary fromNodes(int k, int levels, const std::vector<NodeRecord>& nodes,
                              const std::vector<std::pair<WordId, NodeId>>& words,
                              const std::string& source);

  /// Reads a DBoW2/DBoW3 YAML vocabulary (.yml, .yml.gz, ...) or one written by save(), told
  /// apart by content. Throws VocabularyError naming the file and the field.
  static Vocabulary load(const std::filesystem::path& path);
  /// Writes our binary format (a checked header, the nodes, the words). Throws VocabularyError.
  void save(const std::filesystem::path& path) const;

  bool empty() const { return words_.empty(); }
  int branching() const { return k_; }
  int levels() const { return levels_; }
  std::size_t nodeCount() const { return nodes_.size() - 1; }  ///< without the root
  std::size_t wordCount() const { return words_.size(); }
  const Node& node(NodeId id) const { return nodes_.at(id); }
  NodeId wordNode(WordId word) const { return words_.at(word); }
  double wordWeight(WordId word) const { return nodes_[words_.at(word)].weight; }

  /// The leaf a descriptor falls in, and the node on its path at depth `direct_depth` (the leaf
  /// itself when the leaf is shallower; 0 = the root).
  std::pair<WordId, NodeId> lookup(const BinaryDescriptor& d, int direct_depth) const;

  /// BowVector and FeatureVector of one image's descriptors (CV_8UC1, 32-byte rows; empty gives
  /// empty vectors). Throws std::invalid_argument for another type or width.
  void transform(const cv::Mat& descriptors, BowVector& bow, FeatureVector& features,
                 int direct_depth) const;
  BowVector transform(const cv::Mat& descriptors) const;

 private:
  int k_ = 0;
  int levels_ = 0;
  std::vector<Node> nodes_;    ///< index = node id; nodes_[0] is the root
  std::vector<NodeId> words_;  ///< index = word id
};

}  // namespace tessera::visual_slam
