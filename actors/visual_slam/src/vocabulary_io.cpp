// Vocabulary files: DBoW2/DBoW3 YAML through cv::FileStorage (which also reads .yml.gz), our own
// binary format, and the structural checks both go through (Vocabulary::fromNodes).
//
// Binary format (little-endian, as written on x86-64/ARM64): the 8 bytes "TSVOCAB1", uint32 k,
// L, node count n, word count w; n records {uint32 id, uint32 parent, float64 weight, 32 bytes
// descriptor} breadth first (so children keep their order, which breaks distance ties); w uint32
// node ids, index = word id. Nothing may follow.
#include <tessera/io/atomic_file.hpp>
#include <tessera/visual_slam/vocabulary.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <deque>
#include <fstream>
#include <memory>
#include <sstream>

namespace tessera::visual_slam {

namespace {

constexpr char kMagic[8] = {'T', 'S', 'V', 'O', 'C', 'A', 'B', '1'};

[[noreturn]] void fail(const std::string& source, const std::string& what) {
  throw VocabularyError(source + ": " + what);
}

std::string nodeField(std::size_t i, const char* key) {
  return "vocabulary.nodes[" + std::to_string(i) + "]." + key;
}

}  // namespace

Vocabulary Vocabulary::fromNodes(int k, int levels, const std::vector<NodeRecord>& records,
                                 const std::vector<std::pair<WordId, NodeId>>& words,
                                 const std::string& source) {
  if (k < 2) fail(source, "vocabulary.k = " + std::to_string(k) + ": must be >= 2");
  if (levels < 1) fail(source, "vocabulary.L = " + std::to_string(levels) + ": must be >= 1");
  if (records.empty()) fail(source, "vocabulary.nodes: empty");
  if (words.empty()) fail(source, "vocabulary.words: empty");
  const std::size_t n = records.size();
  Vocabulary v;
  v.k_ = k;
  v.levels_ = levels;
  v.nodes_.resize(n + 1);
  std::vector<std::uint8_t> listed(n + 1, 0);
  for (std::size_t i = 0; i < n; ++i) {
    const auto& r = records[i];
    if (r.id < 1 || r.id > n)
      fail(source, nodeField(i, "nodeId") + " = " + std::to_string(r.id) + ": out of range 1.." +
                       std::to_string(n));
    if (listed[r.id])
      fail(source, nodeField(i, "nodeId") + " = " + std::to_string(r.id) + ": listed twice");
    listed[r.id] = 1;
    if (r.parent > n || r.parent == r.id)
      fail(source, nodeField(i, "parentId") + " = " + std::to_string(r.parent) +
                       ": out of range 0.." + std::to_string(n) + " or the node itself");
    if (!std::isfinite(r.weight) || r.weight < 0)
      fail(source, nodeField(i, "weight") + ": not a finite weight >= 0");
    auto& node = v.nodes_[r.id];
    node.parent = r.parent;
    node.descriptor = r.descriptor;
    node.weight = r.weight;
  }
  for (const auto& r : records) v.nodes_[r.parent].children.push_back(r.id);
  // Depths from the root; a node the root does not reach sits on a cycle of parents.
  std::size_t reached = 0;
  std::deque<NodeId> queue{0};
  while (!queue.empty()) {
    const NodeId id = queue.front();
    queue.pop_front();
    if (v.nodes_[id].children.size() > static_cast<std::size_t>(k))
      fail(source, "vocabulary.nodes: node " + std::to_string(id) + " has " +
                       std::to_string(v.nodes_[id].children.size()) +
                       " children, more than k = " + std::to_string(k));
    for (NodeId c : v.nodes_[id].children) {
      v.nodes_[c].depth = v.nodes_[id].depth + 1;
      if (v.nodes_[c].depth > levels)
        fail(source, "vocabulary.nodes: node " + std::to_string(c) + " at depth " +
                         std::to_string(v.nodes_[c].depth) +
                         ", deeper than L = " + std::to_string(levels));
      ++reached;
      queue.push_back(c);
    }
  }
  if (reached != n)
    fail(source, "vocabulary.nodes: parentId links form a cycle (" + std::to_string(n - reached) +
                     " nodes not reachable from the root)");
  v.words_.assign(words.size(), 0);
  for (std::size_t i = 0; i < words.size(); ++i) {
    const auto [word, id] = words[i];
    const std::string field = "vocabulary.words[" + std::to_string(i) + "]";
    if (word >= words.size())
      fail(source, field + ".wordId = " + std::to_string(word) + ": out of range 0.." +
                       std::to_string(words.size() - 1));
    if (id < 1 || id > n)
      fail(source,
           field + ".nodeId = " + std::to_string(id) + ": out of range 1.." + std::to_string(n));
    if (!v.nodes_[id].children.empty())
      fail(source, field + ".nodeId = " + std::to_string(id) + ": not a leaf");
    if (v.nodes_[id].word >= 0 || v.words_[word] != 0)
      fail(source, field + ": word or node listed twice");
    v.nodes_[id].word = static_cast<int>(word);
    v.words_[word] = id;
  }
  for (NodeId id = 1; id <= n; ++id)
    if (v.nodes_[id].children.empty() && v.nodes_[id].word < 0)
      fail(source, "vocabulary.words: leaf node " + std::to_string(id) + " has no word");
  return v;
}

namespace {

// DBoW3 writes "type cols b0 .. b31" (type 0 = CV_8U); DBoW2 writes the 32 bytes alone.
BinaryDescriptor parseDescriptor(const std::string& text, const std::string& source,
                                 const std::string& field) {
  std::istringstream in(text);
  std::vector<long> values;
  std::string token;
  while (in >> token) {
    char* end = nullptr;
    const long x = std::strtol(token.c_str(), &end, 10);
    if (end == token.c_str() || *end != '\0')
      fail(source, field + ": '" + token + "' is not a number");
    values.push_back(x);
  }
  std::size_t first = 0;
  if (values.size() == kDescriptorBytes + 2) {
    if (values[0] != 0 || values[1] != kDescriptorBytes)
      fail(source, field + ": type " + std::to_string(values[0]) + ", length " +
                       std::to_string(values[1]) + " (expected type 0 = 8-bit, 32 bytes: ORB)");
    first = 2;
  } else if (values.size() != kDescriptorBytes) {
    fail(source, field + ": " + std::to_string(values.size()) +
                     " numbers (expected 32 bytes, optionally after 'type length' as DBoW3 "
                     "writes: 32-byte ORB descriptors only)");
  }
  std::array<std::uint8_t, kDescriptorBytes> bytes{};
  for (std::size_t i = 0; i < bytes.size(); ++i) {
    const long b = values[first + i];
    if (b < 0 || b > 255) fail(source, field + ": byte " + std::to_string(b) + " out of 0..255");
    bytes[i] = static_cast<std::uint8_t>(b);
  }
  return toBinaryDescriptor(bytes.data());
}

int readInt(const cv::FileNode& node, const std::string& source, const std::string& field) {
  if (node.empty() || node.isNone()) fail(source, field + ": missing");
  if (!node.isInt()) fail(source, field + ": not an integer");
  return static_cast<int>(node);
}

Vocabulary loadYaml(const std::filesystem::path& path) {
  const std::string source = path.string();
  cv::FileStorage fs;
  try {
    if (!fs.open(source, cv::FileStorage::READ | cv::FileStorage::FORMAT_AUTO))
      fail(source, "cannot be opened as an OpenCV YAML/XML file");
  } catch (const cv::Exception& e) {
    fail(source, std::string("does not parse as OpenCV YAML/XML (") + e.err + ")");
  }
  try {
    const cv::FileNode voc = fs["vocabulary"];
    if (voc.empty() || !voc.isMap()) fail(source, "vocabulary: missing (top-level map)");
    const int k = readInt(voc["k"], source, "vocabulary.k");
    const int levels = readInt(voc["L"], source, "vocabulary.L");
    const cv::FileNode nodes = voc["nodes"];
    if (nodes.empty() || !nodes.isSeq()) fail(source, "vocabulary.nodes: missing or empty");
    std::vector<Vocabulary::NodeRecord> records;
    records.reserve(nodes.size());
    for (std::size_t i = 0; i < nodes.size(); ++i) {
      const cv::FileNode n = nodes[static_cast<int>(i)];
      if (!n.isMap()) fail(source, "vocabulary.nodes[" + std::to_string(i) + "]: not a map");
      Vocabulary::NodeRecord r;
      const int id = readInt(n["nodeId"], source, nodeField(i, "nodeId"));
      const int parent = readInt(n["parentId"], source, nodeField(i, "parentId"));
      if (id < 0) fail(source, nodeField(i, "nodeId") + " = " + std::to_string(id) + ": negative");
      if (parent < 0)
        fail(source, nodeField(i, "parentId") + " = " + std::to_string(parent) + ": negative");
      r.id = static_cast<NodeId>(id);
      r.parent = static_cast<NodeId>(parent);
      const cv::FileNode w = n["weight"];
      if (w.empty() || w.isNone()) fail(source, nodeField(i, "weight") + ": missing");
      if (!w.isReal() && !w.isInt()) fail(source, nodeField(i, "weight") + ": not a number");
      r.weight = static_cast<double>(w);
      const cv::FileNode d = n["descriptor"];
      if (d.empty() || !d.isString()) fail(source, nodeField(i, "descriptor") + ": missing");
      r.descriptor =
          parseDescriptor(static_cast<std::string>(d), source, nodeField(i, "descriptor"));
      records.push_back(r);
    }
    const cv::FileNode list = voc["words"];
    if (list.empty() || !list.isSeq()) fail(source, "vocabulary.words: missing or empty");
    std::vector<std::pair<WordId, NodeId>> words;
    words.reserve(list.size());
    for (std::size_t i = 0; i < list.size(); ++i) {
      const cv::FileNode n = list[static_cast<int>(i)];
      const std::string field = "vocabulary.words[" + std::to_string(i) + "]";
      if (!n.isMap()) fail(source, field + ": not a map");
      const int word = readInt(n["wordId"], source, field + ".wordId");
      const int id = readInt(n["nodeId"], source, field + ".nodeId");
      if (word < 0 || id < 0) fail(source, field + ": negative id");
      words.emplace_back(static_cast<WordId>(word), static_cast<NodeId>(id));
    }
    return Vocabulary::fromNodes(k, levels, records, words, source);
  } catch (const cv::Exception& e) {
    fail(source, std::string("malformed (") + e.err + ")");
  }
}

template <class T>
void put(std::ostream& out, const T& x) {
  out.write(reinterpret_cast<const char*>(&x), sizeof(T));
}

template <class T>
T get(std::istream& in, const std::string& source, const std::string& field) {
  T x{};
  if (!in.read(reinterpret_cast<char*>(&x), sizeof(T))) fail(source, field + ": truncated");
  return x;
}

Vocabulary loadBinary(const std::filesystem::path& path) {
  const std::string source = path.string();
  std::ifstream in(path, std::ios::binary);
  in.seekg(sizeof(kMagic));
  const auto k = get<std::uint32_t>(in, source, "k");
  const auto levels = get<std::uint32_t>(in, source, "L");
  const auto n = get<std::uint32_t>(in, source, "node count");
  const auto w = get<std::uint32_t>(in, source, "word count");
  // Sizes checked against the file before allocating, so a corrupt count cannot exhaust memory.
  const auto expected =
      sizeof(kMagic) + 16 + std::uintmax_t{n} * (16 + kDescriptorBytes) + std::uintmax_t{w} * 4;
  const auto actual = std::filesystem::file_size(path);
  if (actual != expected)
    fail(source, "size " + std::to_string(actual) + " bytes, expected " + std::to_string(expected) +
                     " for " + std::to_string(n) + " nodes and " + std::to_string(w) +
                     " words (truncated or corrupt)");
  if (k > 1000 || levels > 100) fail(source, "k/L: implausible values (corrupt header)");
  std::vector<Vocabulary::NodeRecord> records(n);
  for (std::uint32_t i = 0; i < n; ++i) {
    const std::string field = "node record " + std::to_string(i);
    records[i].id = get<std::uint32_t>(in, source, field);
    records[i].parent = get<std::uint32_t>(in, source, field);
    records[i].weight = get<double>(in, source, field);
    std::array<std::uint8_t, kDescriptorBytes> bytes{};
    if (!in.read(reinterpret_cast<char*>(bytes.data()), bytes.size()))
      fail(source, field + ": truncated");
    records[i].descriptor = toBinaryDescriptor(bytes.data());
  }
  std::vector<std::pair<WordId, NodeId>> words(w);
  for (std::uint32_t i = 0; i < w; ++i)
    words[i] = {i, get<std::uint32_t>(in, source, "word " + std::to_string(i))};
  return Vocabulary::fromNodes(static_cast<int>(k), static_cast<int>(levels), records, words,
                               source);
}

}  // namespace

Vocabulary Vocabulary::load(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) fail(path.string(), "no such file");
  if (std::filesystem::file_size(path, ec) == 0) fail(path.string(), "empty file");
  char head[sizeof(kMagic)] = {};
  {
    std::ifstream in(path, std::ios::binary);
    in.read(head, sizeof(head));
  }
  if (std::memcmp(head, kMagic, sizeof(kMagic)) == 0) return loadBinary(path);
  return loadYaml(path);
}

void Vocabulary::save(const std::filesystem::path& path) const {
  if (words_.empty()) fail(path.string(), "cannot save an empty vocabulary");
  std::unique_ptr<io::AtomicFile> file;  // the old file or the new one, whole
  try {
    file = std::make_unique<io::AtomicFile>(path);
  } catch (const io::FileWriteError& e) {
    fail(path.string(), e.reason());
  }
  std::ostream& out = file->stream();
  out.write(kMagic, sizeof(kMagic));
  put(out, static_cast<std::uint32_t>(k_));
  put(out, static_cast<std::uint32_t>(levels_));
  put(out, static_cast<std::uint32_t>(nodes_.size() - 1));
  put(out, static_cast<std::uint32_t>(words_.size()));
  std::deque<NodeId> queue{0};
  while (!queue.empty()) {
    const NodeId id = queue.front();
    queue.pop_front();
    for (NodeId c : nodes_[id].children) {
      const auto& node = nodes_[c];
      put(out, c);
      put(out, node.parent);
      put(out, node.weight);
      for (int b = 0; b < kDescriptorBytes; ++b)
        put(out, static_cast<std::uint8_t>(node.descriptor[static_cast<std::size_t>(b / 8)] >>
                                           (8 * (b % 8))));
      queue.push_back(c);
    }
  }
  for (NodeId id : words_) put(out, id);
  try {
    file->commit();
  } catch (const io::FileWriteError& e) {
    fail(path.string(), e.reason());
  }
}

}  // namespace tessera::visual_slam
